#pragma once
// Writes OpenNI2 recordings (.oni) with tessera's own code: a depth stream and, optionally, a
// colour stream, with every property OpenNI2's file player needs to play them back.
// Format summary: ../shared/reference/platform-facts.md and docs/ONI.md.
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "tessera/core/frame.h"

namespace tessera::drivers::oni {

enum class DepthCodec {
  kNone,  // raw 16-bit little-endian millimetres
  k16zT,  // OpenNI's lossless depth codec: per-frame value table + delta tokens
};

enum class ColourCodec {
  kNone,  // raw RGB888
  kJpeg,  // one baseline JFIF image per frame (lossy)
};

struct OniWriterOptions {
  DepthCodec depth_codec = DepthCodec::k16zT;
  ColourCodec colour_codec = ColourCodec::kJpeg;
  int jpeg_quality = 90;  // OpenNI's own recorder uses 90
  int fps = 30;           // reported in the video mode; playback pacing uses timestamps
  bool with_colour = true;
};

// Not thread-safe: one writer thread.
class OniWriter {
 public:
  // Creates `path` and writes the header and stream descriptions. Colour frames must be
  // `colour_size` (registered RGB at the depth size in tessera's frames). Throws core::Error
  // naming the file when it cannot be created.
  OniWriter(const std::filesystem::path& path, const core::Intrinsics& depth_intrinsics,
            cv::Size colour_size, const OniWriterOptions& options = {});
  ~OniWriter();  // closes the file if close() was not called (errors are logged, not thrown)
  OniWriter(const OniWriter&) = delete;
  OniWriter& operator=(const OniWriter&) = delete;

  // Appends one frame (depth, then colour) at frame.timestamp_ns, rounded to microseconds.
  // Timestamps must increase. Throws core::Error on a size mismatch or a failed write.
  void write(const core::Frame& frame);

  // Writes the seek tables and the end record and patches the stream headers. Throws
  // core::Error naming the file when a write fails (e.g. the disk is full).
  void close();

  std::size_t framesWritten() const { return frames_; }

 private:
  struct Stream {
    std::uint32_t node_id = 0;
    std::uint64_t node_added_offset = 0;
    std::uint64_t last_data_offset = 0;
    std::vector<std::uint64_t> frame_offsets;
    std::vector<std::uint64_t> frame_timestamps_us;
  };

  void writeStreamHeader(Stream& stream, bool depth, int width, int height);
  void writeNodeAdded(const Stream& stream, bool depth, std::uint32_t frames, std::uint64_t max_ts,
                      std::uint64_t seek_table_offset);
  void writeFrameRecord(Stream& stream, std::uint64_t timestamp_us,
                        const std::vector<std::uint8_t>& payload);
  std::uint64_t writeRecord(std::uint32_t type, std::uint32_t node_id,
                            const std::vector<std::uint8_t>& fields,
                            const std::vector<std::uint8_t>& payload, std::uint64_t undo);
  void check(const char* what);

  std::filesystem::path path_;
  std::ofstream file_;
  core::Intrinsics intrinsics_;
  cv::Size colour_size_;
  OniWriterOptions options_;
  Stream depth_, colour_;
  std::size_t frames_ = 0;
  std::uint64_t last_timestamp_us_ = 0;
  bool closed_ = false;
};

// Encodes one depth image (CV_16UC1) with the 16zT codec. Exposed for tests.
std::vector<std::uint8_t> encode16zT(const cv::Mat& depth_mm);

}  // namespace tessera::drivers::oni
