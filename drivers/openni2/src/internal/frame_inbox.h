#pragma once
// Frames as OpenNI2's threads hand them over, held for the reader of OpenNi2Source.
#include <optional>
#include <string>

#include <OpenNI.h>

#include "tessera/core/frame_pairing.h"

namespace tessera::drivers::openni2 {

// Shared by OpenNI2's callback threads (writers) and the source's reader, guarded by `mutex`.
// Stamps are the device's microseconds, device_index OpenNI2's frame number; `lost`: the
// device was unplugged.
struct FrameInbox : core::PairingInbox {
  std::optional<int> last_depth_index;  // this connection's last depth frame number

  void clear();  // for a new connection
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
