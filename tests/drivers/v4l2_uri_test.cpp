// v4l2:// URIs and calibration files.
#include <fstream>

#include <gtest/gtest.h>

#include "support/test_data.h"
#include "tessera/core/error.h"
#include "tessera/drivers/v4l2/camera_calibration.h"
#include "tessera/drivers/v4l2/v4l2_device.h"
#include "tessera/drivers/v4l2/v4l2_uri.h"

namespace tessera::drivers::v4l2 {
namespace {

TEST(Uri, ParsesColourAndDepthNodes) {
  const V4l2Uri uri = parseV4l2Uri("v4l2:///dev/video0?depth=/dev/video2");
  EXPECT_EQ(uri.colour_path, "/dev/video0");
  EXPECT_EQ(uri.depth_path, "/dev/video2");
  EXPECT_EQ(uri.profile, "");
  EXPECT_EQ(uri.calibration, "");
}

TEST(Uri, ParsesDepthOnlyProfileAndCalibration) {
  const V4l2Uri depth_only = parseV4l2Uri("v4l2://?depth=/dev/v4l/by-id/usb-cam-video-index0");
  EXPECT_EQ(depth_only.colour_path, "");
  EXPECT_EQ(depth_only.depth_path, "/dev/v4l/by-id/usb-cam-video-index0");

  const V4l2Uri kinect = parseV4l2Uri(
      "v4l2:///dev/video0?profile=kinect_v2&depth=/dev/video2&calibration=/etc/k2.yaml");
  EXPECT_EQ(kinect.colour_path, "/dev/video0");
  EXPECT_EQ(kinect.depth_path, "/dev/video2");
  EXPECT_EQ(kinect.profile, "kinect_v2");
  EXPECT_EQ(kinect.calibration, "/etc/k2.yaml");
  EXPECT_TRUE(isV4l2Uri("v4l2:///dev/video0?depth=/dev/video2"));
  EXPECT_FALSE(isV4l2Uri("/dev/video0"));
}

TEST(Uri, MalformedUrisSayWhatIsWrong) {
  const std::pair<std::string, std::string> cases[] = {
      {"video:///dev/video0?depth=/dev/video2", "starts with v4l2://"},
      {"v4l2:/dev/video0?depth=/dev/video2", "starts with v4l2://"},
      {"v4l2://dev/video0?depth=/dev/video2", "mind the third slash"},
      {"v4l2:///dev/video0", "no depth node"},
      {"v4l2://?", "no depth node"},
      {"v4l2:///dev/video0?depth", "'depth' is not key=value"},
      {"v4l2:///dev/video0?depth=", "'depth=' is not key=value"},
      {"v4l2:///dev/video0?depth=/dev/video2&", "'' is not key=value"},
      {"v4l2:///dev/video0?depth=video2", "depth node 'video2' is not an absolute path"},
      {"v4l2:///dev/video0?depth=/dev/video2&depth=/dev/video3", "'depth' is given twice"},
      {"v4l2:///dev/video0?depth=/dev/video2&fps=30", "unknown key 'fps'"},
      {"v4l2:///dev/video0?depth=/dev/video2&profile=kinect_v3",
       "unknown profile 'kinect_v3'; the profiles are kinect_v2"},
      {"v4l2:///dev/video2?depth=/dev/video2", "the same node"},
  };
  for (const auto& [uri, expected] : cases) {
    try {
      parseV4l2Uri(uri);
      ADD_FAILURE() << uri << " was accepted";
    } catch (const core::ConfigError& e) {
      const std::string message = e.what();
      EXPECT_NE(message.find("'" + uri + "'"), std::string::npos) << message;  // names the URI
      EXPECT_NE(message.find(expected), std::string::npos) << uri << " -> " << message;
    }
  }
}

TEST(Uri, FourccNamesAreReadable) {
  EXPECT_EQ(fourccName(V4L2_PIX_FMT_Z16), "Z16");
  EXPECT_EQ(fourccName(V4L2_PIX_FMT_MJPEG), "MJPG");
  EXPECT_EQ(fourccName(V4L2_PIX_FMT_YUYV), "YUYV");
  EXPECT_EQ(fourccName(0x01020304), "0x01020304");
}

// Writes a calibration file into a fresh folder of this test.
std::filesystem::path writeCalibration(const std::string& text) {
  const auto path = test::freshTempDir() / "calibration.yaml";
  std::ofstream(path) << text;
  return path;
}

const std::string kGood = R"(mirror: false
depth: {width: 4, height: 3, fx: 2.0, fy: 2.0, cx: 1.5, cy: 1.0}
colour: {width: 8, height: 6, fx: 4.0, fy: 4.0, cx: 3.5, cy: 2.5}
T_RGB_D:
  rotation: [0, -1, 0, 1, 0, 0, 0, 0, 1]
  translation_m: [0.01, 0.02, 0.03]
)";

TEST(Calibration, ReadsEveryKey) {
  const CameraCalibration calibration = loadCameraCalibration(writeCalibration(kGood));
  EXPECT_FALSE(calibration.mirror);
  EXPECT_EQ(calibration.depth.width, 4);
  EXPECT_DOUBLE_EQ(calibration.depth.cx, 1.5);
  ASSERT_TRUE(calibration.colour.has_value());
  EXPECT_DOUBLE_EQ(calibration.colour->intrinsics.fx, 4.0);
  const Eigen::Vector3d moved = calibration.colour->T_RGB_D * Eigen::Vector3d(1, 0, 0);
  EXPECT_TRUE(moved.isApprox(Eigen::Vector3d(0.01, 1.02, 0.03))) << moved.transpose();
}

TEST(Calibration, BadFilesNameTheKey) {
  const std::pair<std::string, std::string> cases[] = {
      {"depth: {width: 4, height: 3, fy: 2.0, cx: 1.5, cy: 1.0}\n", "'depth.fx' is missing"},
      {kGood + "fps: 30\n", "unknown key 'fps'"},
      {"depth: {width: 4, height: 3, fx: 2.0, fy: 2.0, cx: 1.5, cy: 1.0}\n"
       "colour: {width: 8, height: 6, fx: 4.0, fy: 4.0, cx: 3.5, cy: 2.5}\n",
       "T_RGB_D needs a rotation"},
      {"depth: {width: 4, height: 3, fx: 2.0, fy: 2.0, cx: 1.5, cy: 1.0}\n"
       "colour: {width: 8, height: 6, fx: 4.0, fy: 4.0, cx: 3.5, cy: 2.5}\n"
       "T_RGB_D: {rotation: [1, 0, 0, 0, 2, 0, 0, 0, 1], translation_m: [0, 0, 0]}\n",
       "T_RGB_D.rotation is not a rotation matrix"},
      {"depth: {width: 0, height: 3, fx: 2.0, fy: 2.0, cx: 1.5, cy: 1.0}\n", "positive width"},
  };
  for (const auto& [text, expected] : cases) {
    try {
      loadCameraCalibration(writeCalibration(text));
      ADD_FAILURE() << "accepted:\n" << text;
    } catch (const core::ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace tessera::drivers::v4l2
