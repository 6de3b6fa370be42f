#include "internal/freenect_inbox.h"

#include "tessera/core/clock.h"

#include <algorithm>
#include <chrono>
#include <cstring>

#include "tessera/drivers/freenect/kinect_v1.h"

namespace tessera::drivers::freenect {

namespace {

constexpr int kWidth = 640;
constexpr int kHeight = 480;

FrameInbox& inboxOf(freenect_device* device) {
  return *static_cast<FrameInbox*>(freenect_get_user(device));
}

// libfreenect's buffers need not be aligned for uint16 (fakenect's follow a PGM header), so
// frames are copied bytewise before they are read as pixels.
cv::Mat copyImage(const void* data, int type, std::size_t bytes) {
  cv::Mat image(kHeight, kWidth, type);
  if (bytes < image.total() * image.elemSize()) image.setTo(0);
  std::memcpy(image.data, data, std::min(bytes, image.total() * image.elemSize()));
  return image;
}

}  // namespace

std::int64_t DeviceClock::unwrap(std::uint32_t stamp) {
  if (!started_) {
    started_ = true;
    last_ticks_ = stamp;
  } else {
    // Modular difference, read as signed: the nearest placement of the new stamp.
    last_ticks_ += static_cast<std::int32_t>(stamp - last_stamp_);
  }
  last_stamp_ = stamp;
  return last_ticks_;
}

void FrameInbox::clear() {
  clearFrames();
  clock = DeviceClock();
  lost = false;
  loss_code = 0;
}

namespace {

// libfreenect calls back from inside libusb: nothing may escape (std::terminate), so a frame
// that cannot be copied is counted as dropped.
template <typename Take>
void guarded(FrameInbox& inbox, bool is_depth, Take take) {
  try {
    take();
  } catch (const std::exception&) {
    std::lock_guard lock(inbox.mutex);
    if (is_depth) {
      ++inbox.delivered;
      ++inbox.dropped;
    }
  }
}

void takeDepth(FrameInbox& inbox, void* data, std::uint32_t timestamp) {
  core::CapturedImage frame;
  frame.arrival_ns = core::steadyNowNs();
  cv::Mat image = copyImage(data, CV_16UC1, inbox.depth_bytes);
  frame.image = inbox.depth_in_mm ? image : disparityImageToMm(image);
  std::lock_guard lock(inbox.mutex);
  frame.stamp = inbox.clock.unwrap(timestamp);
  inbox.pushDepth(std::move(frame));
}

void takeColour(FrameInbox& inbox, void* data, std::uint32_t timestamp) {
  core::CapturedImage frame;
  frame.arrival_ns = core::steadyNowNs();
  frame.image = copyImage(data, CV_8UC3, inbox.colour_bytes);
  std::lock_guard lock(inbox.mutex);
  frame.stamp = inbox.clock.unwrap(timestamp);
  inbox.pushColour(std::move(frame));
}

}  // namespace

void onDepth(freenect_device* device, void* data, std::uint32_t timestamp) {
  FrameInbox& inbox = inboxOf(device);
  guarded(inbox, true, [&] { takeDepth(inbox, data, timestamp); });
}

void onColour(freenect_device* device, void* data, std::uint32_t timestamp) {
  FrameInbox& inbox = inboxOf(device);
  guarded(inbox, false, [&] { takeColour(inbox, data, timestamp); });
}

}  // namespace tessera::drivers::freenect
