#include "tessera/drivers/v4l2/camera_calibration.h"

#include <algorithm>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "tessera/core/error.h"
#include "tessera/drivers/v4l2/v4l2_uri.h"

namespace tessera::drivers::v4l2 {

namespace {

core::Intrinsics readIntrinsics(const core::ConfigSection& section) {
  core::Intrinsics k;
  section.read("fx", k.fx);
  section.read("fy", k.fy);
  section.read("cx", k.cx);
  section.read("cy", k.cy);
  section.read("width", k.width);
  section.read("height", k.height);
  return k;
}

core::Isometry readTransform(const core::ConfigSection& section) {
  std::vector<double> rotation, translation;
  section.read("rotation", rotation);
  section.read("translation_m", translation);
  const std::string& origin = section.origin();
  if (rotation.size() != 9 || translation.size() != 3) {
    throw core::ConfigError(fmt::format(
        "{}: T_RGB_D needs a rotation of 9 numbers (row-major) and translation_m of 3", origin));
  }
  Eigen::Matrix3d R;
  R << rotation[0], rotation[1], rotation[2], rotation[3], rotation[4], rotation[5], rotation[6],
      rotation[7], rotation[8];
  // A typo in a rotation matrix is easy and silently skews every colour sample.
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-3 ||
      R.determinant() < 0.0) {
    throw core::ConfigError(fmt::format("{}: T_RGB_D.rotation is not a rotation matrix", origin));
  }
  core::Isometry T = core::Isometry::Identity();
  T.linear() = R;
  T.translation() = Eigen::Vector3d(translation[0], translation[1], translation[2]);
  return T;
}

}  // namespace

CameraCalibration readCameraCalibration(const core::ConfigDocument& document) {
  const core::ConfigSection root = document.root();
  CameraCalibration calibration;
  root.read("mirror", calibration.mirror);
  calibration.depth = readIntrinsics(root.section("depth"));
  if (root.has("colour")) {
    core::ColourCamera colour;
    colour.intrinsics = readIntrinsics(root.section("colour"));
    colour.T_RGB_D = readTransform(root.section("T_RGB_D"));
    calibration.colour = colour;
  }
  document.checkAllKeysUsed();
  const auto absent = document.keysAskedButAbsent();
  for (const std::string& key : absent) {
    if (key != "mirror") {
      throw core::ConfigError(
          fmt::format("{}: calibration key '{}' is missing", document.origin(), key));
    }
  }
  const bool colour_valid = !calibration.colour || calibration.colour->intrinsics.valid();
  if (!calibration.depth.valid() || !colour_valid) {
    throw core::ConfigError(
        fmt::format("{}: intrinsics need non-zero focal lengths and a positive width and height",
                    document.origin()));
  }
  return calibration;
}

CameraCalibration loadCameraCalibration(const std::filesystem::path& path) {
  return readCameraCalibration(core::ConfigDocument::load(path));
}

V4l2Profile kinectV2Profile() {
  V4l2Profile profile;
  profile.name = "kinect_v2";
  profile.calibration = std::filesystem::path(TESSERA_V4L2_CONFIG_DIR) / "kinect_v2.yaml";
  profile.depth_width = 512;
  profile.depth_height = 424;
  profile.colour_width = 1920;
  profile.colour_height = 1080;
  return profile;
}

V4l2Profile profileByName(const std::string& name) {
  if (name == "kinect_v2") return kinectV2Profile();
  throw core::ConfigError(fmt::format("unknown V4L2 profile '{}'; the profiles are {}", name,
                                      fmt::join(knownV4l2Profiles(), ", ")));
}

}  // namespace tessera::drivers::v4l2
