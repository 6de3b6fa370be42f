#pragma once
// The messages of a ROS 1 bag as serialized bytes, topic by topic in record order: read through
// librosbag's index, or, for a bag whose index was never written (the recorder was killed) or
// is cut off, salvaged by walking its records from the start.
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace tessera::drivers::ros1 {

struct RawMessage {
  std::string topic;
  std::string datatype;        // e.g. sensor_msgs/Image
  std::int64_t record_ns = 0;  // when the recorder received it
  std::vector<std::uint8_t> bytes;
};

struct TopicSummary {
  std::string datatype;
  std::size_t messages = 0;
};

class BagMessages {
 public:
  virtual ~BagMessages() = default;
  virtual const std::map<std::string, TopicSummary>& topics() const = 0;
  // Starts again from the first message, keeping only those on `topics`.
  virtual void select(const std::set<std::string>& topics) = 0;
  // The next selected message; nothing at the end.
  virtual std::optional<RawMessage> next() = 0;
};

// Opens `path` through librosbag, or salvages it when its index is missing or cut off
// (`salvage_note` then says what happened, for a warning). Throws core::SourceError naming the
// file when it is not a ROS 1 bag (format 2.0) at all.
std::unique_ptr<BagMessages> openBagMessages(const std::filesystem::path& path,
                                             std::string& salvage_note);

// Walks the records of a bag without its index. Exposed for tests.
std::unique_ptr<BagMessages> salvageBagMessages(const std::filesystem::path& path,
                                                std::string& salvage_note);

}  // namespace tessera::drivers::ros1
