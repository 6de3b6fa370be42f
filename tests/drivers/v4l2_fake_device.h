#pragma once
// A V4L2 camera simulated in memory, behind the driver's V4l2Device seam, and the payloads it
// streams. Every scripted frame is ready at once; after the last one the node stalls or fails
// as the script says, the way an unplugged or hung camera does.
#include <cerrno>
#include <cstdint>
#include <deque>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "tessera/drivers/v4l2/v4l2_device.h"

namespace tessera::drivers::v4l2::fake {

struct FakeFrame {
  std::int64_t timestamp_ns = 0;
  std::vector<std::uint8_t> bytes;  // fewer than the format's frame size: a short read
  bool flagged_error = false;       // V4L2_BUF_FLAG_ERROR
};

enum class FakeEnding {
  kStall,               // poll() times out for ever
  kDisappearOnDequeue,  // poll() reports the node ready, VIDIOC_DQBUF fails with end_errno
  kPollError,           // poll() itself fails with end_errno
};

// One node's script, shared by the test (which reads the counters afterwards) and the device.
struct FakeCamera {
  std::string path;
  std::vector<std::uint32_t> formats;  // offered, in VIDIOC_ENUM_FMT order
  int width = 0;                       // the only size the node streams at
  int height = 0;
  std::uint32_t device_caps = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_STREAMING;
  std::vector<FakeFrame> frames;
  FakeEnding ending = FakeEnding::kStall;
  int end_errno = ENODEV;

  // Observed
  std::uint32_t set_fourcc = 0;
  std::uint32_t buffers_granted = 0;
  int opens = 0, closes = 0, maps = 0, unmaps = 0, streams_on = 0, streams_off = 0;
  std::size_t delivered = 0;
};

// Follows the V4L2 rules the capture relies on and fails with EINVAL where a real driver
// would (dequeue before streaming, queueing a buffer twice or unmapped, ...).
class FakeV4l2Device : public V4l2Device {
 public:
  explicit FakeV4l2Device(std::shared_ptr<FakeCamera> camera) : camera_(std::move(camera)) {}

  int open(const std::string& path) override;
  void close() override;
  int queryCapabilities(v4l2_capability& caps) override;
  int enumerateFormat(v4l2_fmtdesc& desc) override;
  int getFormat(v4l2_format& format) override;
  int tryFormat(v4l2_format& format) override;
  int setFormat(v4l2_format& format) override;
  int requestBuffers(v4l2_requestbuffers& request) override;
  int queryBuffer(v4l2_buffer& buffer) override;
  int map(std::uint32_t offset, std::uint32_t length, void*& start) override;
  int unmap(void* start, std::uint32_t length) override;
  int queueBuffer(v4l2_buffer& buffer) override;
  int dequeueBuffer(v4l2_buffer& buffer) override;
  int streamOn() override;
  int streamOff() override;
  int waitForFrame(int timeout_ms, bool& ready) override;

 private:
  void fillLayout(v4l2_pix_format& pix) const;

  std::shared_ptr<FakeCamera> camera_;
  bool open_ = false;
  bool streaming_ = false;
  v4l2_format format_{};
  std::vector<std::vector<std::uint8_t>> buffers_;
  std::vector<bool> mapped_;
  std::vector<bool> queued_flag_;
  std::deque<std::uint32_t> queued_;
};

// Devices for the given cameras, found by path; any other path fails to open (ENOENT).
DeviceFactory fakeFactory(std::vector<std::shared_ptr<FakeCamera>> cameras);

// Payloads as the node would deliver them.
std::vector<std::uint8_t> z16Bytes(const cv::Mat& depth_mm);  // CV_16UC1, little-endian
std::vector<std::uint8_t> rgb24Bytes(const cv::Mat& rgb);     // CV_8UC3 R, G, B
// BT.601 limited range ("video range"), each pixel pair sharing the mean of its chroma: the
// plain formula, written out as the reference for the conversion under test.
std::vector<std::uint8_t> yuyvBytes(const cv::Mat& rgb);
std::vector<std::uint8_t> mjpegBytes(const cv::Mat& rgb, int quality);

}  // namespace tessera::drivers::v4l2::fake
