// Texturing and view evaluation agree to a fraction of a texel: a wall with fine sinusoidal
// detail, seen at known poses, is mapped; its patches rendered back at those poses put each
// stripe where the camera saw it. A half-texel slip in either side's pixel rule, texel centres
// or texture coordinates would shift every render by about 0.6 px and fail here.
#include <cmath>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "support/synthetic_plane.h"
#include "support/test_data.h"
#include "tessera/eval/view_render.h"
#include "tessera/pipeline/run.h"

namespace tessera::pipeline {
namespace {

constexpr double kWallZ = 2.0;      // the wall is the plane z = 2 m of the world
constexpr double kPeriodX = 0.021;  // stripe periods, metres: 6 and 7.4 texels of 3.5 mm
constexpr double kPeriodY = 0.026;

cv::Vec3b wallColour(const Eigen::Vector3d& X) {
  const double a = std::sin(2.0 * M_PI * X.x() / kPeriodX);
  const double b = std::cos(2.0 * M_PI * X.y() / kPeriodY);
  return {cv::saturate_cast<std::uint8_t>(128 + 80 * a),
          cv::saturate_cast<std::uint8_t>(128 + 80 * b),
          cv::saturate_cast<std::uint8_t>(128 + 40 * (a - b))};
}

core::Isometry viewPose(int i) {
  core::Isometry T_W_C = core::Isometry::Identity();
  // Sub-pixel steps between views, so that the cells blend samples from many pixel phases.
  T_W_C.translation() = Eigen::Vector3d(0.0137 * i - 0.08, 0.0091 * i - 0.05, 0.6 + 0.004 * i);
  T_W_C.linear() = (Eigen::AngleAxisd(0.004 * (i - 6), Eigen::Vector3d::UnitY()) *
                    Eigen::AngleAxisd(0.003 * (i - 6), Eigen::Vector3d::UnitX()))
                       .toRotationMatrix();
  return T_W_C;
}

// Exact depth and the wall's colour at every pixel centre, as a camera at viewPose(i) sees it.
class WallSource : public core::FrameSource {
 public:
  explicit WallSource(int frames) : frames_(frames) {}
  core::ReadResult read() override {
    if (next_ == frames_) return {};
    const int i = next_++;
    core::ReadResult result;
    result.status = core::ReadStatus::kFrame;
    result.frame = capture(i);
    return result;
  }
  static core::Frame capture(int i) {
    const core::Isometry T_W_C = viewPose(i);
    core::Frame frame =
        test::renderPlane(test::kinectIntrinsics(), T_W_C, Eigen::Vector3d(0, 0, 1), kWallZ);
    const core::Intrinsics& k = frame.intrinsics;
    for (int v = 0; v < k.height; ++v) {
      for (int u = 0; u < k.width; ++u) {
        const Eigen::Vector3d ray =
            T_W_C.linear() * Eigen::Vector3d((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
        const double t = (kWallZ - T_W_C.translation().z()) / ray.z();
        frame.rgb.at<cv::Vec3b>(v, u) = wallColour(T_W_C.translation() + t * ray);
      }
    }
    frame.index = static_cast<std::uint64_t>(i);
    frame.timestamp_ns = static_cast<std::int64_t>(i) * 33'333'333;
    frame.T_W_C_gt = T_W_C;
    return frame;
  }
  std::string name() const override { return "striped wall"; }
  std::optional<std::size_t> frameCount() const override {
    return static_cast<std::size_t>(frames_);
  }

 private:
  int frames_;
  int next_ = 0;
};

cv::Mat grey(const cv::Mat& rgb, const cv::Rect& box) {
  cv::Mat g;
  cv::cvtColor(rgb(box), g, cv::COLOR_RGB2GRAY);
  g.convertTo(g, CV_64F);
  return g;
}

// The sub-pixel shift d with got(x + d) closest to want(x) in the least-squares sense: one
// Lucas-Kanade step, exact to first order for the fraction of a pixel a misplacement makes.
// (Phase correlation, whose peak is found by a centroid, is biased on a few pure stripes.)
cv::Point2d shiftBetween(const cv::Mat& want, const cv::Mat& got) {
  cv::Mat gx, gy;
  cv::Sobel(got, gx, CV_64F, 1, 0, 3, 1.0 / 8.0);
  cv::Sobel(got, gy, CV_64F, 0, 1, 3, 1.0 / 8.0);
  Eigen::Matrix2d normal = Eigen::Matrix2d::Zero();
  Eigen::Vector2d rhs = Eigen::Vector2d::Zero();
  for (int y = 1; y + 1 < got.rows; ++y) {
    for (int x = 1; x + 1 < got.cols; ++x) {
      const Eigen::Vector2d g(gx.at<double>(y, x), gy.at<double>(y, x));
      normal += g * g.transpose();
      rhs += g * (want.at<double>(y, x) - got.at<double>(y, x));
    }
  }
  const Eigen::Vector2d d = normal.ldlt().solve(rhs);
  return {d.x(), d.y()};
}

TEST(TexelPlacement, PatchesRenderedAtTheirViewsPutFineDetailWithinAQuarterPixel) {
  constexpr int kFrames = 12;  // 1.4 m from the wall: a pixel is 2.7 mm there, a texel 3.5
  WallSource source(kFrames);
  RunOptions options;
  options.out_dir = test::freshTempDir();
  options.poses = PoseSource::kGroundTruth;
  RunConfig config = loadRunConfig(std::nullopt);
  config.tsdf.integrate_every_n_frames = 1;
  const RunSummary summary = runPipeline(source, config, options);
  ASSERT_GE(summary.patches.patches_finalized, 1u);
  const eval::RenderMesh map = eval::readTexturedObj(options.out_dir / "patches.obj");

  // The middle of the image, which every view's wall patch covers.
  const cv::Rect box(160, 120, 320, 240);
  for (int i = 0; i < kFrames; ++i) {
    const core::Frame frame = WallSource::capture(i);
    const eval::ViewImage view = eval::renderView(map, frame.intrinsics, viewPose(i));
    // No crack: every pixel of the box is drawn (quads per run of cells, joined at
    // T-junctions with rounded vertices, left hairlines uncovered).
    ASSERT_EQ(cv::countNonZero(view.depth(box) > 0.0F), box.area()) << "view " << i;
    const cv::Mat want = grey(frame.rgb, box), got = grey(view.rgb, box);
    const cv::Point2d shift = shiftBetween(want, got);
    // Measured 0.004 px at most; 0.05 px is 0.14 mm on the wall, 1/25 of a texel.
    EXPECT_LT(std::abs(shift.x), 0.05) << "view " << i;
    EXPECT_LT(std::abs(shift.y), 0.05) << "view " << i;

    // Stripes of 6 to 7.4 texels keep most of their contrast through the cells' box filter and
    // the render's bilinear lookup.
    cv::Mat error;
    cv::absdiff(want, got, error);
    const double rms = std::sqrt(cv::mean(error.mul(error))[0]);
    EXPECT_LT(rms, 7.0) << "view " << i;  // measured 5.3, against the stripes' 36 grey rms
  }
}

}  // namespace
}  // namespace tessera::pipeline
