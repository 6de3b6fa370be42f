// Reads a ROS 1 bag (format 2.0) record by record, without its index: what a recorder that was
// killed, or a copy that was cut off, leaves. A record is a length-prefixed header of
// "name=value" fields (op says which record), then length-prefixed data. Messages (op 0x02)
// and their topics' connections (op 0x07) sit inside chunks (op 0x05), stored plain, bz2 or lz4.
#include <bzlib.h>
#include <roslz4/lz4s.h>

#include <cstring>
#include <deque>
#include <fstream>

#include <fmt/format.h>

#include "internal/bag_messages.h"
#include "tessera/core/error.h"

namespace tessera::drivers::ros1 {

namespace {

constexpr char kMagic[] = "#ROSBAG V2.0\n";
constexpr std::size_t kMagicSize = sizeof(kMagic) - 1;
constexpr std::uint8_t kOpMessage = 0x02;
constexpr std::uint8_t kOpChunk = 0x05;
constexpr std::uint8_t kOpConnection = 0x07;

std::uint32_t readU32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
         static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
}

using Fields = std::map<std::string, std::string>;

// "len name=value" fields; nothing when they do not fit in the header.
std::optional<Fields> parseFields(const std::uint8_t* p, std::size_t size) {
  Fields fields;
  std::size_t at = 0;
  while (at + 4 <= size) {
    const std::uint32_t length = readU32(p + at);
    at += 4;
    if (length > size - at) return std::nullopt;
    const std::string field(reinterpret_cast<const char*>(p + at), length);
    at += length;
    const auto equals = field.find('=');
    if (equals == std::string::npos) return std::nullopt;
    fields[field.substr(0, equals)] = field.substr(equals + 1);
  }
  if (at != size) return std::nullopt;
  return fields;
}

std::uint8_t op(const Fields& fields) {
  const auto it = fields.find("op");
  return it == fields.end() || it->second.size() != 1 ? 0
                                                      : static_cast<std::uint8_t>(it->second[0]);
}

std::uint32_t u32Field(const Fields& fields, const char* name) {
  const auto it = fields.find(name);
  if (it == fields.end() || it->second.size() != 4) return 0;
  return readU32(reinterpret_cast<const std::uint8_t*>(it->second.data()));
}

struct Record {
  Fields fields;
  std::vector<std::uint8_t> data;
  bool cut = false;  // the data ends early
};

struct Connection {
  std::string topic;
  std::string datatype;
};

// Connection header data: the same "len name=value" fields; "type" is the message type.
std::string datatypeOf(const std::vector<std::uint8_t>& data) {
  const auto fields = parseFields(data.data(), data.size());
  if (!fields) return "";
  const auto it = fields->find("type");
  return it == fields->end() ? "" : it->second;
}

class SalvagedBag : public BagMessages {
 public:
  SalvagedBag(std::filesystem::path path, std::string& note) : path_(std::move(path)) {
    open();
    // One pass to learn the topics and count their messages.
    std::map<std::uint32_t, std::size_t> counts;
    std::size_t records = 0;
    while (auto record = nextRecord()) {
      forEachInner(*record, [&](const Record& inner) {
        if (op(inner.fields) == kOpMessage) ++counts[u32Field(inner.fields, "conn")];
      });
      ++records;
    }
    for (const auto& [id, count] : counts) {
      const auto it = connections_.find(id);
      if (it == connections_.end()) continue;  // its connection record was lost
      TopicSummary& summary = topics_[it->second.topic];
      summary.datatype = it->second.datatype;
      summary.messages += count;
    }
    std::size_t messages = 0;
    for (const auto& [topic, summary] : topics_) messages += summary.messages;
    note = fmt::format("salvaged {} messages on {} topics from {} records{}", messages,
                       topics_.size(), records, stop_note_.empty() ? "" : "; " + stop_note_);
  }

  const std::map<std::string, TopicSummary>& topics() const override { return topics_; }

  void select(const std::set<std::string>& topics) override {
    selected_ = topics;
    pending_.clear();
    open();
  }

  std::optional<RawMessage> next() override {
    while (pending_.empty()) {
      auto record = nextRecord();
      if (!record) return std::nullopt;
      forEachInner(*record, [&](const Record& inner) {
        if (op(inner.fields) != kOpMessage || inner.cut) return;
        const auto it = connections_.find(u32Field(inner.fields, "conn"));
        if (it == connections_.end() || !selected_.count(it->second.topic)) return;
        const auto time = inner.fields.find("time");
        if (time == inner.fields.end() || time->second.size() != 8) return;
        const auto* t = reinterpret_cast<const std::uint8_t*>(time->second.data());
        RawMessage raw;
        raw.topic = it->second.topic;
        raw.datatype = it->second.datatype;
        raw.record_ns = static_cast<std::int64_t>(readU32(t)) * 1'000'000'000 + readU32(t + 4);
        raw.bytes = inner.data;
        pending_.push_back(std::move(raw));
      });
    }
    RawMessage raw = std::move(pending_.front());
    pending_.pop_front();
    return raw;
  }

 private:
  void open() {
    file_ = std::ifstream(path_, std::ios::binary);
    char magic[kMagicSize] = {};
    if (!file_.read(magic, kMagicSize) || std::memcmp(magic, kMagic, kMagicSize) != 0) {
      throw core::SourceError(
          fmt::format("{}: not a ROS 1 bag (no '#ROSBAG V2.0' header)", path_.string()));
    }
    stop_note_.clear();
  }

  // The next top-level record, nothing at the end of the file or at a record cut off before
  // its data starts.
  std::optional<Record> nextRecord() {
    std::uint8_t length[4];
    if (!file_.read(reinterpret_cast<char*>(length), 4)) return std::nullopt;
    std::vector<std::uint8_t> header(readU32(length));
    if (header.size() > (1u << 20) || !file_.read(reinterpret_cast<char*>(header.data()),
                                                  static_cast<std::streamsize>(header.size()))) {
      stop_note_ = fmt::format("cut off at byte {}", static_cast<long long>(file_.tellg()));
      return std::nullopt;
    }
    Record record;
    auto fields = parseFields(header.data(), header.size());
    if (!fields || !file_.read(reinterpret_cast<char*>(length), 4)) {
      stop_note_ = "cut off inside a record header";
      return std::nullopt;
    }
    record.fields = std::move(*fields);
    record.data.resize(readU32(length));
    file_.read(reinterpret_cast<char*>(record.data.data()),
               static_cast<std::streamsize>(record.data.size()));
    if (file_.gcount() != static_cast<std::streamsize>(record.data.size())) {
      record.data.resize(static_cast<std::size_t>(file_.gcount()));
      record.cut = true;
      stop_note_ = "the last record is cut off";
      file_.setstate(std::ios::eofbit);
    }
    if (op(record.fields) == kOpConnection) learnConnection(record);
    return record;
  }

  void learnConnection(const Record& record) {
    const auto topic = record.fields.find("topic");
    if (topic == record.fields.end()) return;
    connections_.emplace(u32Field(record.fields, "conn"),
                         Connection{topic->second, datatypeOf(record.data)});
  }

  // Calls `visit` with `record` itself, or with each whole record inside it when it is a chunk
  // (connections inside are learnt on the way).
  template <typename Visit>
  void forEachInner(const Record& record, Visit visit) {
    if (op(record.fields) != kOpChunk) {
      visit(record);
      return;
    }
    const std::vector<std::uint8_t> content = chunkContent(record);
    std::size_t at = 0;
    while (at + 4 <= content.size()) {
      const std::uint32_t header_size = readU32(content.data() + at);
      if (header_size > content.size() - at - 4) break;
      auto fields = parseFields(content.data() + at + 4, header_size);
      at += 4 + header_size;
      if (!fields || at + 4 > content.size()) break;
      const std::uint32_t data_size = readU32(content.data() + at);
      at += 4;
      Record inner;
      inner.fields = std::move(*fields);
      const std::size_t available = std::min<std::size_t>(data_size, content.size() - at);
      inner.data.assign(content.begin() + static_cast<std::ptrdiff_t>(at),
                        content.begin() + static_cast<std::ptrdiff_t>(at + available));
      inner.cut = available < data_size;
      at += available;
      if (op(inner.fields) == kOpConnection) learnConnection(inner);
      visit(inner);
    }
  }

  std::vector<std::uint8_t> chunkContent(const Record& chunk) {
    const auto compression = chunk.fields.find("compression");
    const std::string method = compression == chunk.fields.end() ? "none" : compression->second;
    if (method == "none") return chunk.data;  // a cut chunk keeps its whole records
    if (chunk.cut) return {};                 // a cut compressed stream cannot be unpacked
    std::vector<std::uint8_t> out(u32Field(chunk.fields, "size"));
    auto out_size = static_cast<unsigned int>(out.size());
    auto* in = reinterpret_cast<char*>(const_cast<std::uint8_t*>(chunk.data.data()));
    const auto in_size = static_cast<unsigned int>(chunk.data.size());
    bool ok = false;
    if (method == "bz2") {
      ok = BZ2_bzBuffToBuffDecompress(reinterpret_cast<char*>(out.data()), &out_size, in, in_size,
                                      0, 0) == BZ_OK;
    } else if (method == "lz4") {
      ok = roslz4_buffToBuffDecompress(in, in_size, reinterpret_cast<char*>(out.data()),
                                       &out_size) == ROSLZ4_OK;
    }
    if (!ok) return {};
    out.resize(out_size);
    return out;
  }

  std::filesystem::path path_;
  std::ifstream file_;
  std::map<std::uint32_t, Connection> connections_;
  std::map<std::string, TopicSummary> topics_;
  std::set<std::string> selected_;
  std::deque<RawMessage> pending_;
  std::string stop_note_;
};

}  // namespace

std::unique_ptr<BagMessages> salvageBagMessages(const std::filesystem::path& path,
                                                std::string& salvage_note) {
  return std::make_unique<SalvagedBag>(path, salvage_note);
}

}  // namespace tessera::drivers::ros1
