#pragma once
// Streaming capture from one V4L2 node: format negotiation, mmap buffers, poll and dequeue.
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "tessera/drivers/v4l2/v4l2_device.h"

namespace tessera::drivers::v4l2 {

// The pixel formats tessera converts, in order of preference.
const std::vector<std::uint32_t>& depthFormatPreferences();   // Z16, Y16
const std::vector<std::uint32_t>& colourFormatPreferences();  // YUYV, MJPEG, RGB24

struct CaptureConfig {
  std::string path;                    // /dev/videoN, named in every message
  std::string role = "depth";          // "depth" or "colour", for messages
  std::vector<std::uint32_t> formats;  // wanted FourCCs, most preferred first
  int width = 0;                       // pixels; 0 keeps the node's current size
  int height = 0;                      // pixels; 0 keeps the node's current size
  std::string size_reason;             // why that size, for the message when the node refuses it
  int buffer_count = 4;                // mmap streaming buffers
  int stall_timeout_ms = 2000;         // no frame for this long ends the stream
};

// What the node agreed to deliver.
struct PixelFormat {
  std::uint32_t fourcc = 0;
  int width = 0;
  int height = 0;
  std::uint32_t bytes_per_line = 0;  // 0 for compressed formats
  std::uint32_t size_image = 0;      // bytes of a full frame (an upper bound for MJPEG)
};

// True for formats whose frames have a fixed size (all but MJPEG).
bool isUncompressed(std::uint32_t fourcc);

enum class CaptureStatus {
  kImage,     // `bytes` holds a frame
  kBadImage,  // this frame is unusable (short, flagged as corrupt); `problem` says why
  kTimeout,   // nothing arrived within the wait, but the stall timeout has not passed
  kEnd,       // the stream is over (device gone, stalled, failed); `problem` says why
};

struct CaptureResult {
  CaptureStatus status = CaptureStatus::kEnd;
  cv::Mat bytes;                  // 1 x n CV_8UC1 copy of the frame, as the node delivered it
  std::int64_t timestamp_ns = 0;  // the buffer's timestamp (CLOCK_MONOTONIC for UVC nodes)
  std::uint32_t sequence = 0;     // the driver's frame counter; gaps are dropped frames
  std::string problem;
};

// Opens the node, negotiates the first format of `config.formats` the node offers, maps
// `buffer_count` buffers, queues them and starts streaming; the destructor stops the stream
// and releases everything. Throws core::SourceError naming the path when the node cannot be
// opened, is not a streaming capture node, or offers none of the wanted formats (the message
// lists the formats it does offer). Not thread-safe: one reader.
class V4l2Capture {
 public:
  V4l2Capture(std::unique_ptr<V4l2Device> device, CaptureConfig config);
  ~V4l2Capture();
  V4l2Capture(const V4l2Capture&) = delete;
  V4l2Capture& operator=(const V4l2Capture&) = delete;

  // The next frame, copied out of its buffer, which goes straight back to the driver. Waits at
  // most `timeout_ms`, and ends the stream once no frame came for the stall timeout.
  CaptureResult next(int timeout_ms);

  const PixelFormat& format() const { return format_; }
  const std::string& path() const { return config_.path; }
  // Every FourCC the node listed (VIDIOC_ENUM_FMT).
  const std::vector<std::uint32_t>& offeredFormats() const { return offered_; }
  std::size_t framesDequeued() const { return dequeued_; }

 private:
  struct Buffer {
    void* start = nullptr;
    std::uint32_t length = 0;
  };
  void setUp();
  void negotiate();
  void startStreaming();
  void release();
  CaptureResult end(std::string problem);
  std::string deviceFailure(const char* operation, int error) const;

  std::unique_ptr<V4l2Device> device_;
  CaptureConfig config_;
  PixelFormat format_;
  std::vector<std::uint32_t> offered_;
  std::vector<Buffer> buffers_;
  bool opened_ = false;
  bool buffers_requested_ = false;
  bool streaming_ = false;
  bool ended_ = false;
  std::string end_problem_;  // why the stream ended, reported by the next call
  std::size_t dequeued_ = 0;
  std::chrono::steady_clock::time_point last_frame_;
};

}  // namespace tessera::drivers::v4l2
