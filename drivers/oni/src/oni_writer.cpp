#include "tessera/drivers/oni/oni_writer.h"

#include <cmath>
#include <cstring>
#include <limits>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "internal/oni_format.h"
#include "tessera/core/error.h"

namespace tessera::drivers::oni {

namespace {

using namespace format;  // NOLINT: the record names read best unqualified here
constexpr std::uint64_t kNoLimit = std::numeric_limits<std::uint64_t>::max();
// Seek-table entries carry a non-zero configuration id so the player never mistakes them for
// the all-zero entry 0.
constexpr std::uint32_t kConfigurationId = 1;

std::uint32_t fourcc(const char (&code)[5]) {
  return static_cast<std::uint32_t>(code[0]) | static_cast<std::uint32_t>(code[1]) << 8 |
         static_cast<std::uint32_t>(code[2]) << 16 | static_cast<std::uint32_t>(code[3]) << 24;
}

// Little-endian field builder.
class Bytes {
 public:
  Bytes& u8(std::uint8_t v) { return raw(&v, 1); }
  Bytes& u16(std::uint16_t v) { return le(v, 2); }
  Bytes& u32(std::uint32_t v) { return le(v, 4); }
  Bytes& u64(std::uint64_t v) { return le(v, 8); }
  Bytes& f64(double v) {
    std::uint64_t bits;
    std::memcpy(&bits, &v, 8);
    return le(bits, 8);
  }
  // Length-prefixed string; the length counts the terminating NUL, which is written too.
  Bytes& str(const std::string& s) {
    u32(static_cast<std::uint32_t>(s.size() + 1));
    raw(s.c_str(), s.size() + 1);
    return *this;
  }
  Bytes& raw(const void* data, std::size_t n) {
    const auto* p = static_cast<const std::uint8_t*>(data);
    bytes_.insert(bytes_.end(), p, p + n);
    return *this;
  }
  const std::vector<std::uint8_t>& data() const { return bytes_; }

 private:
  Bytes& le(std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i) bytes_.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
    return *this;
  }
  std::vector<std::uint8_t> bytes_;
};

Bytes outputMode(int width, int height, int fps) {
  Bytes mode;
  mode.u32(static_cast<std::uint32_t>(width)).u32(static_cast<std::uint32_t>(height));
  mode.u32(static_cast<std::uint32_t>(fps));
  return mode;
}

}  // namespace

OniWriter::OniWriter(const std::filesystem::path& path, const core::Intrinsics& depth_intrinsics,
                     cv::Size colour_size, const OniWriterOptions& options)
    : path_(path), intrinsics_(depth_intrinsics), colour_size_(colour_size), options_(options) {
  if (!intrinsics_.valid()) {
    throw core::Error(fmt::format("{}: cannot record without valid intrinsics ({})", path.string(),
                                  intrinsics_.describe()));
  }
  file_.open(path, std::ios::binary | std::ios::trunc);
  if (!file_) throw core::Error(fmt::format("{}: cannot create the recording", path.string()));

  depth_.node_id = 1;
  colour_.node_id = options_.with_colour ? 2 : 0;
  // File header: magic, version 1.0.1.0, largest timestamp (none given), largest node id.
  Bytes header;
  header.raw("NI10", 4).u8(1).u8(0).u16(1).u32(0).u64(kNoLimit);
  header.u32(options_.with_colour ? 2 : 1);
  file_.write(reinterpret_cast<const char*>(header.data().data()),
              static_cast<std::streamsize>(header.data().size()));

  writeStreamHeader(depth_, true, intrinsics_.width, intrinsics_.height);
  if (options_.with_colour)
    writeStreamHeader(colour_, false, colour_size_.width, colour_size_.height);
  Bytes begin;
  begin.u32(0xFFFFFFFF).u64(kNoLimit);
  writeRecord(kNodeDataBegin, depth_.node_id, begin.data(), {}, 0);
  if (options_.with_colour) writeRecord(kNodeDataBegin, colour_.node_id, begin.data(), {}, 0);
  check("writing the stream headers");
}

OniWriter::~OniWriter() {
  if (closed_) return;
  try {
    close();
  } catch (const core::Error& e) {
    spdlog::error("{}", e.what());
  }
}

void OniWriter::writeNodeAdded(const Stream& stream, bool depth, std::uint32_t frames,
                               std::uint64_t max_ts, std::uint64_t seek_table_offset) {
  Bytes fields;
  fields.str(depth ? "Depth" : "Image");
  fields.u32(depth ? kDepthNode : kImageNode);
  const bool raw = depth ? options_.depth_codec == DepthCodec::kNone
                         : options_.colour_codec == ColourCodec::kNone;
  fields.u32(raw ? fourcc("NONE") : fourcc(depth ? "16zT" : "JPEG"));
  fields.u32(frames).u64(0).u64(max_ts).u64(seek_table_offset);
  writeRecord(kNodeAdded, stream.node_id, fields.data(), {}, 0);
}

void OniWriter::writeStreamHeader(Stream& stream, bool depth, int width, int height) {
  stream.node_added_offset = static_cast<std::uint64_t>(file_.tellp());
  writeNodeAdded(stream, depth, 0xFFFFFFFF, kNoLimit, 0);  // patched by close()

  const auto int_property = [&](const std::string& name, std::uint64_t value) {
    Bytes fields;
    fields.str(name).u32(8).u64(value);
    writeRecord(kIntProperty, stream.node_id, fields.data(), {}, 0);
  };
  const auto general_property = [&](const std::string& name, const Bytes& value) {
    Bytes fields;
    fields.str(name).u32(static_cast<std::uint32_t>(value.data().size()));
    fields.raw(value.data().data(), value.data().size());
    writeRecord(kGeneralProperty, stream.node_id, fields.data(), {}, 0);
  };

  const int bytes_per_pixel = depth ? 2 : 3;
  int_property("oniRequiredFrameSize",
               static_cast<std::uint64_t>(width * height * bytes_per_pixel));
  int_property("xnIsGenerating", 1);
  if (depth) int_property("xnDeviceMaxDepth", 10000);  // Kinect-class range, in millimetres
  int_property("xnSupportedMapOutputModesCount", 1);
  general_property("xnSupportedMapOutputModes", outputMode(width, height, options_.fps));
  general_property("xnMapOutputMode", outputMode(width, height, options_.fps));
  Bytes formats;
  formats.u32(depth ? 1u << 3 : 1u << 0);  // Gray16 or RGB24
  general_property("xnSupportedPixelFormats", formats);
  int_property("xnPixelFormat", depth ? 4 : 1);       // Gray16 / RGB24
  int_property("oniPixelFormat", depth ? 100 : 200);  // DEPTH_1_MM / RGB888
  // Field of view of the pinhole model (registered colour shares the depth camera's).
  const double scale_x = static_cast<double>(width) / intrinsics_.width;
  const double scale_y = static_cast<double>(height) / intrinsics_.height;
  Bytes fov;
  fov.f64(2.0 * std::atan(width / (2.0 * std::abs(intrinsics_.fx) * scale_x)));
  fov.f64(2.0 * std::atan(height / (2.0 * std::abs(intrinsics_.fy) * scale_y)));
  general_property("xnFOV", fov);
  Bytes cropping;  // disabled; the player needs the property to deliver frames
  cropping.u32(0).u16(0).u16(0).u16(0).u16(0);
  general_property("xnCropping", cropping);
  int_property("xnMirror", 0);
  writeRecord(kNodeStateReady, stream.node_id, {}, {}, 0);
}

std::uint64_t OniWriter::writeRecord(std::uint32_t type, std::uint32_t node_id,
                                     const std::vector<std::uint8_t>& fields,
                                     const std::vector<std::uint8_t>& payload, std::uint64_t undo) {
  const auto offset = static_cast<std::uint64_t>(file_.tellp());
  Bytes header;
  header.u32(kRecordMagic).u32(type).u32(node_id);
  header.u32(static_cast<std::uint32_t>(kRecordHeaderBytes + fields.size()));
  header.u32(static_cast<std::uint32_t>(payload.size())).u64(undo);
  file_.write(reinterpret_cast<const char*>(header.data().data()), kRecordHeaderBytes);
  file_.write(reinterpret_cast<const char*>(fields.data()),
              static_cast<std::streamsize>(fields.size()));
  file_.write(reinterpret_cast<const char*>(payload.data()),
              static_cast<std::streamsize>(payload.size()));
  return offset;
}

void OniWriter::writeFrameRecord(Stream& stream, std::uint64_t timestamp_us,
                                 const std::vector<std::uint8_t>& payload) {
  Bytes fields;
  fields.u64(timestamp_us).u32(static_cast<std::uint32_t>(stream.frame_offsets.size() + 1));
  // Undo points at the stream's previous frame: the player's backward seek follows it.
  stream.last_data_offset =
      writeRecord(kNewData, stream.node_id, fields.data(), payload, stream.last_data_offset);
  stream.frame_offsets.push_back(stream.last_data_offset);
  stream.frame_timestamps_us.push_back(timestamp_us);
}

void OniWriter::write(const core::Frame& frame) {
  if (closed_) throw core::Error(fmt::format("{}: write after close", path_.string()));
  if (frame.depth_mm.type() != CV_16UC1 || frame.depth_mm.cols != intrinsics_.width ||
      frame.depth_mm.rows != intrinsics_.height) {
    throw core::Error(fmt::format("{}: frame {} depth is {}x{}, the recording is {}x{} 16-bit",
                                  path_.string(), frame.index, frame.depth_mm.cols,
                                  frame.depth_mm.rows, intrinsics_.width, intrinsics_.height));
  }
  if (options_.with_colour && (frame.rgb.type() != CV_8UC3 || frame.rgb.size() != colour_size_)) {
    throw core::Error(fmt::format("{}: frame {} colour is {}x{}, the recording is {}x{} RGB",
                                  path_.string(), frame.index, frame.rgb.cols, frame.rgb.rows,
                                  colour_size_.width, colour_size_.height));
  }
  const auto timestamp_us = static_cast<std::uint64_t>((frame.timestamp_ns + 500) / 1000);
  if (frames_ > 0 && timestamp_us <= last_timestamp_us_) {
    throw core::Error(fmt::format("{}: frame {} timestamp {} us does not increase", path_.string(),
                                  frame.index, timestamp_us));
  }
  last_timestamp_us_ = timestamp_us;

  const cv::Mat depth = frame.depth_mm.isContinuous() ? frame.depth_mm : frame.depth_mm.clone();
  std::vector<std::uint8_t> payload;
  if (options_.depth_codec == DepthCodec::k16zT) {
    payload = encode16zT(depth);
  } else {
    const auto* bytes = depth.ptr<std::uint8_t>();  // x86 is little-endian, as the format
    payload.assign(bytes, bytes + depth.total() * 2);
  }
  writeFrameRecord(depth_, timestamp_us, payload);

  if (options_.with_colour) {
    const cv::Mat rgb = frame.rgb.isContinuous() ? frame.rgb : frame.rgb.clone();
    if (options_.colour_codec == ColourCodec::kJpeg) {
      cv::Mat bgr;
      cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
      cv::imencode(".jpg", bgr, payload, {cv::IMWRITE_JPEG_QUALITY, options_.jpeg_quality});
    } else {
      payload.assign(rgb.ptr<std::uint8_t>(), rgb.ptr<std::uint8_t>() + rgb.total() * 3);
    }
    writeFrameRecord(colour_, timestamp_us, payload);
  }
  ++frames_;
  check("writing a frame");
}

void OniWriter::close() {
  if (closed_) return;
  closed_ = true;
  std::vector<Stream*> streams = {&depth_};
  if (options_.with_colour) streams.push_back(&colour_);
  std::vector<std::uint64_t> seek_offsets;
  for (Stream* stream : streams) {
    writeRecord(kNodeRemoved, stream->node_id, {}, {}, stream->node_added_offset);
    Bytes table;
    table.u64(0).u32(0).u64(0);  // entry 0: frames are numbered from 1
    for (std::size_t i = 0; i < stream->frame_offsets.size(); ++i) {
      table.u64(stream->frame_timestamps_us[i]).u32(kConfigurationId).u64(stream->frame_offsets[i]);
    }
    seek_offsets.push_back(writeRecord(kSeekTable, stream->node_id, {}, table.data(), 0));
  }
  writeRecord(kEnd, 0, {}, {}, 0);
  // Patch each stream's description with its frame count, last timestamp and seek table.
  for (std::size_t s = 0; s < streams.size(); ++s) {
    file_.seekp(static_cast<std::streamoff>(streams[s]->node_added_offset));
    writeNodeAdded(*streams[s], s == 0,
                   static_cast<std::uint32_t>(streams[s]->frame_offsets.size()), last_timestamp_us_,
                   seek_offsets[s]);
  }
  file_.flush();
  check("finishing the recording");
  file_.close();
  if (!file_) throw core::Error(fmt::format("{}: closing the recording failed", path_.string()));
}

void OniWriter::check(const char* what) {
  if (!file_) {
    throw core::Error(
        fmt::format("{}: {} failed (disk full or no permission?)", path_.string(), what));
  }
}

}  // namespace tessera::drivers::oni
