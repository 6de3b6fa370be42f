#include "internal/frame_inbox.h"

#include "tessera/core/clock.h"

namespace tessera::drivers::openni2 {

void FrameInbox::clear() {
  clearFrames();
  lost = false;
  last_depth_index.reset();
}

void InboxListener::onNewFrame(openni::VideoStream& stream) {
  // Called on OpenNI2's thread: nothing may escape it (std::terminate), so a frame that cannot
  // be copied is counted as dropped.
  try {
    take(stream);
  } catch (const std::exception&) {
    std::lock_guard lock(inbox_.mutex);
    if (is_depth_) {
      ++inbox_.delivered;
      ++inbox_.dropped;
    }
  }
}

void InboxListener::take(openni::VideoStream& stream) {
  // A callback may find nothing to read: its frame was taken along with an earlier one, or the
  // streams are stopping. readFrame would then wait for the next frame, which never comes once
  // the device has gone, and closing the device would wait on this callback for ever.
  openni::VideoStream* streams[] = {&stream};
  int ready = -1;
  if (openni::OpenNI::waitForAnyStream(streams, 1, &ready, 0) != openni::STATUS_OK) return;
  openni::VideoFrameRef ref;
  if (stream.readFrame(&ref) != openni::STATUS_OK || !ref.isValid()) return;
  core::CapturedImage frame;
  frame.arrival_ns = core::steadyNowNs();
  frame.stamp = static_cast<std::int64_t>(ref.getTimestamp());  // microseconds
  frame.device_index = ref.getFrameIndex();
  const int format = ref.getVideoMode().getPixelFormat();
  const cv::Mat view(ref.getHeight(), ref.getWidth(), is_depth_ ? CV_16UC1 : CV_8UC3,
                     const_cast<void*>(ref.getData()),
                     static_cast<std::size_t>(ref.getStrideInBytes()));
  if (format == openni::PIXEL_FORMAT_DEPTH_100_UM) {
    view.convertTo(frame.image, CV_16UC1, 0.1);  // 100 um units to millimetres
  } else {
    frame.image = view.clone();
  }
  std::lock_guard lock(inbox_.mutex);
  if (is_depth_) {
    // OpenNI2 keeps only the newest frame for a listener that is still busy: gaps in its frame
    // numbers are frames the device sent that never reached us.
    const int missed = inbox_.last_depth_index && frame.device_index > *inbox_.last_depth_index
                           ? frame.device_index - *inbox_.last_depth_index - 1
                           : 0;
    inbox_.last_depth_index = frame.device_index;
    inbox_.pushDepth(std::move(frame), static_cast<std::size_t>(missed));
  } else {
    inbox_.pushColour(std::move(frame));
  }
}

void DisconnectWatch::watch(const std::string& uri) {
  std::lock_guard lock(inbox_.mutex);
  uri_ = uri;
}

void DisconnectWatch::onDeviceDisconnected(const openni::DeviceInfo* info) {
  std::lock_guard lock(inbox_.mutex);
  if (info == nullptr || uri_ != info->getUri()) return;
  inbox_.lost = true;
  inbox_.changed.notify_all();
}

}  // namespace tessera::drivers::openni2
