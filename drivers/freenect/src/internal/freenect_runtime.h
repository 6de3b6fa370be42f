#pragma once
// libfreenect contexts and the modes the freenect source asks for.
#include <memory>
#include <string>

#include <libfreenect.h>

namespace tessera::drivers::freenect {

struct ContextDeleter {
  void operator()(freenect_context* context) const { freenect_shutdown(context); }
};
using Context = std::unique_ptr<freenect_context, ContextDeleter>;

// A context for the camera subdevice only (the motor and audio are not used), logging through
// spdlog. Throws core::SourceError naming `label` when libfreenect cannot start.
Context openContext(const std::string& label);

struct DepthMode {
  freenect_frame_mode mode{};
  bool registered = false;  // millimetres registered to colour, else raw 11-bit disparity
};

// FREENECT_DEPTH_REGISTERED at 640x480 when the library offers it, else FREENECT_DEPTH_11BIT.
// The modes are looked up in the library's list, not by freenect_find_depth_mode: fakenect
// asserts on any mode it lacks. Throws core::SourceError naming `label` when neither is offered.
DepthMode chooseDepthMode(const std::string& label);
// FREENECT_VIDEO_RGB at 640x480. Throws core::SourceError naming `label` when not offered.
freenect_frame_mode chooseColourMode(const std::string& label);

}  // namespace tessera::drivers::freenect
