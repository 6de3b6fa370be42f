// The kinect_v2 profile: calibration file, un-mirroring and colour-to-depth registration.
#include <cmath>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "drivers/v4l2_fake_device.h"
#include "support/test_data.h"
#include "tessera/core/error.h"
#include "tessera/core/registration.h"
#include "tessera/drivers/v4l2/v4l2_source.h"

namespace tessera::drivers::v4l2 {
namespace {

const cv::Vec3b kMarker(230, 20, 20), kBackground(200, 200, 200);
constexpr double kMarkerRadiusM = 0.03;

std::filesystem::path kinectCalibration() {
  return test::sourceDir() / "config" / "kinect_v2.yaml";
}

// The point where a camera's ray through pixel (u, v) meets the plane n . X = d (that
// camera's coordinates). Plain arithmetic: the images below are rendered pixel by pixel.
Eigen::Vector3d onPlane(const core::Intrinsics& k, double u, double v, const Eigen::Vector3d& n,
                        double d) {
  const double x = (u - k.cx) / k.fx, y = (v - k.cy) / k.fy;
  const double z = d / (n.x() * x + n.y() * y + n.z());
  return {x * z, y * z, z};
}

// A square plate of the plane, 2 * half_px wide around depth pixel (u0, v0), before empty space
// (0 depth, which registration skips; that keeps the test fast in sanitizer builds).
cv::Mat renderDepth(const core::Intrinsics& k, const Eigen::Vector3d& n, double d, int u0, int v0,
                    int half_px) {
  cv::Mat depth_mm(k.height, k.width, CV_16UC1, cv::Scalar(0));
  for (int v = v0 - half_px; v < v0 + half_px; ++v) {
    auto* row = depth_mm.ptr<std::uint16_t>(v);
    for (int u = u0 - half_px; u < u0 + half_px; ++u) {
      row[u] = static_cast<std::uint16_t>(std::lround(onPlane(k, u, v, n, d).z() * 1000.0));
    }
  }
  return depth_mm;
}

// The plane as the colour camera sees it, with a disc of kMarkerRadiusM around P. Only a window
// around P's image is traced (the disc spans about 25 pixels); the rest is background.
cv::Mat renderColour(const core::Intrinsics& k, const Eigen::Vector3d& n, double d,
                     const Eigen::Vector3d& P) {
  cv::Mat rgb(k.height, k.width, CV_8UC3,
              cv::Scalar(kBackground[0], kBackground[1], kBackground[2]));
  const int centre_u = static_cast<int>(k.fx * P.x() / P.z() + k.cx);
  const int centre_v = static_cast<int>(k.fy * P.y() / P.z() + k.cy);
  constexpr int kWindow = 100;
  for (int v = std::max(centre_v - kWindow, 0); v < std::min(centre_v + kWindow, k.height); ++v) {
    auto* row = rgb.ptr<cv::Vec3b>(v);
    for (int u = std::max(centre_u - kWindow, 0); u < std::min(centre_u + kWindow, k.width); ++u) {
      const Eigen::Vector3d X = onPlane(k, u, v, n, d);
      const double dx = X.x() - P.x(), dy = X.y() - P.y(), dz = X.z() - P.z();
      if (dx * dx + dy * dy + dz * dz < kMarkerRadiusM * kMarkerRadiusM) row[u] = kMarker;
    }
  }
  return rgb;
}

TEST(KinectV2, CalibrationFileHoldsTheProfileSizesAndAnExtrinsic) {
  const CameraCalibration calibration = loadCameraCalibration(kinectCalibration());
  EXPECT_EQ(calibration.depth.width, 512);
  EXPECT_EQ(calibration.depth.height, 424);
  EXPECT_NEAR(calibration.depth.fx, 365.5, 1e-9);
  ASSERT_TRUE(calibration.colour.has_value());
  EXPECT_EQ(calibration.colour->intrinsics.width, 1920);
  EXPECT_EQ(calibration.colour->intrinsics.height, 1080);
  EXPECT_NEAR(calibration.colour->T_RGB_D.translation().norm(), 0.052, 1e-9);
  EXPECT_TRUE(calibration.mirror);
}

// A plane seen by both Kinect v2 cameras with the file's calibration; a red disc on it must
// land, after un-mirroring and registration, on the depth pixel its centre projects to.
TEST(KinectV2, MarkerSeenByColourLandsOnItsDepthPixel) {
  const CameraCalibration calibration = loadCameraCalibration(kinectCalibration());
  const core::Intrinsics& kd = calibration.depth;
  const core::Intrinsics& kc = calibration.colour->intrinsics;
  const core::Isometry& T_RGB_D = calibration.colour->T_RGB_D;
  const Eigen::Vector3d n_D = Eigen::Vector3d(0.15, -0.1, -1.0).normalized();
  const double d_D = n_D.dot(Eigen::Vector3d(0.0, 0.0, 1.6));
  const int marker_u = 360, marker_v = 150;  // off-centre: a mirrored image misses it
  const Eigen::Vector3d P_D = onPlane(kd, marker_u, marker_v, n_D, d_D);

  cv::Mat depth_mm = renderDepth(kd, n_D, d_D, marker_u, marker_v, 60);
  // The colour camera's view: the plane and the marker centre moved into its frame.
  const Eigen::Vector3d n_C = T_RGB_D.linear() * n_D;
  const cv::Mat rgb = renderColour(kc, n_C, d_D + n_C.dot(T_RGB_D.translation()), T_RGB_D * P_D);
  ASSERT_TRUE(calibration.mirror);
  cv::flip(depth_mm, depth_mm, 1);  // as libfreenect2 delivers them
  cv::Mat rgb_delivered;
  cv::flip(rgb, rgb_delivered, 1);

  auto depth_node = std::make_shared<fake::FakeCamera>();
  depth_node->path = "/dev/video2";
  depth_node->formats = {V4L2_PIX_FMT_Z16};
  depth_node->width = kd.width, depth_node->height = kd.height;
  depth_node->frames.push_back({1'000'000'000, fake::z16Bytes(depth_mm), false});
  auto colour_node = std::make_shared<fake::FakeCamera>();
  colour_node->path = "/dev/video0";
  colour_node->formats = {V4L2_PIX_FMT_RGB24};
  colour_node->width = kc.width, colour_node->height = kc.height;
  colour_node->frames.push_back({1'002'000'000, fake::rgb24Bytes(rgb_delivered), false});
  V4l2Options options;
  options.make_device = fake::fakeFactory({depth_node, colour_node});
  V4l2Source source("v4l2:///dev/video0?depth=/dev/video2&profile=kinect_v2", options);

  const core::ReadResult result = source.read();
  ASSERT_EQ(result.status, core::ReadStatus::kFrame) << result.problem;
  const core::Frame& frame = result.frame;
  ASSERT_TRUE(frame.colour_camera.has_value());
  EXPECT_EQ(frame.rgb.size(), cv::Size(1920, 1080));
  EXPECT_EQ(frame.depth_mm.at<std::uint16_t>(marker_v, marker_u),
            std::lround(P_D.z() * 1000.0));  // un-mirrored depth

  const cv::Mat registered = core::registerColourToDepth(frame);
  ASSERT_EQ(registered.size(), frame.depth_mm.size());
  cv::Mat red;
  cv::inRange(registered, cv::Scalar(150, 0, 0), cv::Scalar(255, 100, 100), red);
  const cv::Moments m = cv::moments(red, true);
  ASSERT_GT(m.m00, 50.0) << "the marker is missing from the registered colour";
  EXPECT_NEAR(m.m10 / m.m00, marker_u, 1.0);
  EXPECT_NEAR(m.m01 / m.m00, marker_v, 1.0);
}

TEST(KinectV2, ProfileRefusesANodeAtAnotherSize) {
  auto depth_node = std::make_shared<fake::FakeCamera>();
  depth_node->path = "/dev/video2";
  depth_node->formats = {V4L2_PIX_FMT_Z16};
  depth_node->width = 640, depth_node->height = 480;
  V4l2Options options;
  options.make_device = fake::fakeFactory({depth_node});
  try {
    V4l2Source source("v4l2://?depth=/dev/video2&profile=kinect_v2", options);
    FAIL() << "a 640x480 depth node was accepted as a Kinect v2";
  } catch (const core::SourceError& e) {
    EXPECT_NE(std::string(e.what()).find("asked for 512x424 Z16, the node delivers 640x480"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace tessera::drivers::v4l2
