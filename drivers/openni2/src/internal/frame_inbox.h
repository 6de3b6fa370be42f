#pragma once
// Frames as OpenNI2's threads hand them over, held for the reader of OpenNi2Source.
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <string>

#include <OpenNI.h>
#include <opencv2/core/mat.hpp>

namespace tessera::drivers::openni2 {

struct CapturedFrame {
  std::int64_t timestamp_us = 0;  // device clock
  std::int64_t arrival_ns = 0;    // host steady clock (core::steadyNowNs)
  int device_index = 0;           // OpenNI2's frame number
  cv::Mat image;                  // depth CV_16UC1 millimetres, or colour CV_8UC3 RGB
};

// Shared by OpenNI2's callback threads (writers) and the source's reader; every field is
// guarded by `mutex`.
struct FrameInbox {
  std::mutex mutex;
  std::condition_variable changed;
  std::deque<CapturedFrame> depth;
  std::deque<CapturedFrame> colour;
  std::size_t depth_capacity = 2;   // a busy reader loses the oldest depth frames
  std::size_t colour_capacity = 8;  // enough to pair with any depth frame still held
  std::size_t delivered = 0;
  std::size_t dropped = 0;
  bool lost = false;                    // the device was unplugged
  std::optional<int> last_depth_index;  // this connection's last depth frame number

  void clear();
};

// Copies each new frame of one stream into the inbox (the usual OpenNI2 listener pattern).
class InboxListener : public openni::VideoStream::NewFrameListener {
 public:
  InboxListener(FrameInbox& inbox, bool is_depth) : inbox_(inbox), is_depth_(is_depth) {}
  void onNewFrame(openni::VideoStream& stream) override;

 private:
  void take(openni::VideoStream& stream);

  FrameInbox& inbox_;
  bool is_depth_;
};

// Marks the inbox lost when OpenNI2 reports that this device was unplugged.
class DisconnectWatch : public openni::OpenNI::DeviceDisconnectedListener {
 public:
  explicit DisconnectWatch(FrameInbox& inbox) : inbox_(inbox) {}
  void watch(const std::string& uri);
  void onDeviceDisconnected(const openni::DeviceInfo* info) override;

 private:
  FrameInbox& inbox_;
  std::string uri_;  // guarded by inbox_.mutex
};

}  // namespace tessera::drivers::openni2
