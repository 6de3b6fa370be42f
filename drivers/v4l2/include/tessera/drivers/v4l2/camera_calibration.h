#pragma once
// Camera geometry of a V4L2 depth + colour pair, and the device profiles that bring their own.
#include <filesystem>
#include <optional>
#include <string>

#include "tessera/core/config.h"
#include "tessera/core/frame.h"

namespace tessera::drivers::v4l2 {

// Everything describes the images as the source hands them on, i.e. after un-mirroring.
struct CameraCalibration {
  core::Intrinsics depth;                    // with width and height: the size to ask for
  std::optional<core::ColourCamera> colour;  // absent: colour is registered to depth
  // The device delivers both images mirrored left-right (libfreenect2 does, as the Kinect v2
  // SDK does); the source flips them back so that the camera frames are right-handed.
  bool mirror = false;
};

// Reads a calibration file laid out as config/kinect_v2.yaml: `depth` and `colour` intrinsics
// (fx, fy, cx, cy, width, height), `T_RGB_D` (row-major `rotation`, `translation_m`) and
// `mirror`. `colour` and `T_RGB_D` go together or not at all. Throws core::ConfigError naming
// the file and the key that is missing, unknown or wrong (e.g. a rotation that is not one).
CameraCalibration readCameraCalibration(const core::ConfigDocument& document);
CameraCalibration loadCameraCalibration(const std::filesystem::path& path);

// A named device profile: the sizes it streams at and its default calibration file.
struct V4l2Profile {
  std::string name;
  std::filesystem::path calibration;        // used when the URI names no calibration file
  int depth_width = 0, depth_height = 0;    // pixels the depth node must deliver
  int colour_width = 0, colour_height = 0;  // pixels the colour node must deliver
};

// Kinect v2 as libfreenect2 delivers it: depth 512x424 (16-bit mm), colour 1920x1080, both
// mirrored; calibration from config/kinect_v2.yaml in the source tree.
V4l2Profile kinectV2Profile();

// Throws core::ConfigError listing the known profiles for another name.
V4l2Profile profileByName(const std::string& name);

}  // namespace tessera::drivers::v4l2
