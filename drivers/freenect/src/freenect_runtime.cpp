#include "internal/freenect_runtime.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "tessera/core/error.h"

namespace tessera::drivers::freenect {

namespace {

void logMessage(freenect_context* /*context*/, freenect_loglevel level, const char* message) {
  std::string text = message == nullptr ? "" : message;
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r')) text.pop_back();
  if (level <= FREENECT_LOG_ERROR) {
    spdlog::error("libfreenect: {}", text);
  } else if (level <= FREENECT_LOG_WARNING) {
    spdlog::warn("libfreenect: {}", text);
  } else {
    spdlog::debug("libfreenect: {}", text);
  }
}

}  // namespace

Context openContext(const std::string& label) {
  freenect_context* raw = nullptr;
  if (freenect_init(&raw, nullptr) < 0 || raw == nullptr) {
    throw core::SourceError(fmt::format("{}: libfreenect cannot start (no USB access?)", label));
  }
  Context context(raw);
  freenect_set_log_callback(raw, logMessage);
  freenect_set_log_level(raw, FREENECT_LOG_WARNING);
  freenect_select_subdevices(raw, FREENECT_DEVICE_CAMERA);
  return context;
}

DepthMode chooseDepthMode(const std::string& label) {
  DepthMode chosen;
  bool found = false;
  std::string offered;
  for (int i = 0; i < freenect_get_depth_mode_count(); ++i) {
    const freenect_frame_mode mode = freenect_get_depth_mode(i);
    offered += fmt::format("{}{}x{} format {}", offered.empty() ? "" : ", ", mode.width,
                           mode.height, static_cast<int>(mode.depth_format));
    if (!mode.is_valid || mode.resolution != FREENECT_RESOLUTION_MEDIUM) continue;
    if (mode.depth_format == FREENECT_DEPTH_REGISTERED) return {mode, true};
    if (mode.depth_format == FREENECT_DEPTH_11BIT && !found) {
      chosen = {mode, false};
      found = true;
    }
  }
  if (!found) {
    throw core::SourceError(fmt::format(
        "{}: libfreenect offers neither registered nor 11-bit depth at 640x480; it offers: {}",
        label, offered));
  }
  return chosen;
}

freenect_frame_mode chooseColourMode(const std::string& label) {
  for (int i = 0; i < freenect_get_video_mode_count(); ++i) {
    const freenect_frame_mode mode = freenect_get_video_mode(i);
    if (mode.is_valid && mode.resolution == FREENECT_RESOLUTION_MEDIUM &&
        mode.video_format == FREENECT_VIDEO_RGB)
      return mode;
  }
  throw core::SourceError(fmt::format("{}: libfreenect offers no 640x480 RGB video mode", label));
}

}  // namespace tessera::drivers::freenect
