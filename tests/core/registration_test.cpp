#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "support/synthetic_plane.h"
#include "tessera/core/registration.h"

namespace tessera::core {
namespace {

TEST(Registration, ColourFromABesideCameraLandsOnTheRightDepthPixels) {
  const Intrinsics k = test::kinectIntrinsics();
  const Eigen::Vector3d n = Eigen::Vector3d(0.1, -0.2, -1.0).normalized();
  const double d = n.dot(Eigen::Vector3d(0, 0, 1.2));
  const Isometry T_W_D = Isometry::Identity();
  Isometry T_D_RGB = Isometry::Identity();
  T_D_RGB.translation().x() = 0.025;  // a Kinect's colour camera sits 2.5 cm to the side

  const Frame registered = test::renderPlane(k, T_W_D, n, d);  // colour seen from depth
  Frame unregistered = registered;
  unregistered.rgb = test::renderPlane(k, T_W_D * T_D_RGB, n, d).rgb;  // from the side
  unregistered.colour_camera = ColourCamera{k, T_D_RGB.inverse()};

  // Unregistered, the checkerboard is shifted by about f * b / z = 11 pixels.
  const cv::Rect inner(40, 40, 560, 400);
  const auto mismatch = [&](const cv::Mat& a) {
    cv::Mat diff;
    cv::absdiff(a(inner), registered.rgb(inner), diff);
    cv::Mat grey;
    cv::cvtColor(diff, grey, cv::COLOR_RGB2GRAY);
    return static_cast<double>(cv::countNonZero(grey > 20)) / static_cast<double>(inner.area());
  };
  EXPECT_GT(mismatch(unregistered.rgb), 0.05);
  const Frame fixed = withRegisteredColour(unregistered);
  EXPECT_FALSE(fixed.colour_camera.has_value());
  EXPECT_LT(mismatch(fixed.rgb), 0.02);  // only checker edges, sampled differently, differ
}

TEST(Registration, RegisteredFramesAreLeftAlone) {
  const Frame frame = test::renderPlane(test::kinectIntrinsics(), Isometry::Identity(),
                                        Eigen::Vector3d(0, 0, -1), -1.5);
  const cv::Mat same = registerColourToDepth(frame);
  EXPECT_EQ(same.data, frame.rgb.data);
}

}  // namespace
}  // namespace tessera::core
