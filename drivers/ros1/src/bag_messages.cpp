#include "internal/bag_messages.h"

#include <fmt/format.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>

#include "tessera/core/error.h"

namespace tessera::drivers::ros1 {

namespace {

// librosbag's index: each selected topic's messages in record order.
class IndexedBag : public BagMessages {
 public:
  explicit IndexedBag(const std::filesystem::path& path) {
    bag_.open(path.string(), rosbag::bagmode::Read);
    rosbag::View all(bag_);
    for (const rosbag::ConnectionInfo* connection : all.getConnections()) {
      topics_[connection->topic].datatype = connection->datatype;
    }
    for (auto& [topic, summary] : topics_) {
      summary.messages = rosbag::View(bag_, rosbag::TopicQuery(topic)).size();
    }
  }

  const std::map<std::string, TopicSummary>& topics() const override { return topics_; }

  void select(const std::set<std::string>& topics) override {
    view_ = std::make_unique<rosbag::View>(
        bag_, rosbag::TopicQuery(std::vector<std::string>(topics.begin(), topics.end())));
    it_ = view_->begin();
  }

  std::optional<RawMessage> next() override {
    if (!view_ || it_ == view_->end()) return std::nullopt;
    const rosbag::MessageInstance& m = *it_;
    RawMessage raw;
    raw.topic = m.getTopic();
    raw.datatype = m.getDataType();
    raw.record_ns = static_cast<std::int64_t>(m.getTime().toNSec());
    raw.bytes.resize(m.size());
    ros::serialization::OStream stream(raw.bytes.data(),
                                       static_cast<std::uint32_t>(raw.bytes.size()));
    m.write(stream);
    ++it_;
    return raw;
  }

 private:
  rosbag::Bag bag_;
  std::map<std::string, TopicSummary> topics_;
  std::unique_ptr<rosbag::View> view_;
  rosbag::View::iterator it_;
};

}  // namespace

std::unique_ptr<BagMessages> openBagMessages(const std::filesystem::path& path,
                                             std::string& salvage_note) {
  salvage_note.clear();
  try {
    return std::make_unique<IndexedBag>(path);
  } catch (const rosbag::BagUnindexedException&) {
    auto salvaged = salvageBagMessages(path, salvage_note);
    salvage_note = "its index was never written (was the recorder stopped?); " + salvage_note;
    return salvaged;
  } catch (const rosbag::BagException& e) {
    // A cut-off file fails here too: its index lies past the end. The records before the cut
    // may still be whole.
    auto salvaged = salvageBagMessages(path, salvage_note);
    salvage_note = fmt::format("librosbag cannot read it ({}); {}", e.what(), salvage_note);
    return salvaged;
  }
}

}  // namespace tessera::drivers::ros1
