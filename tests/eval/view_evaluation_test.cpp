// The view evaluation on a scene whose answer is known: a textured wall seen from a few poses.
// A map that places the texture where it is scores high; the same map shifted by 1 cm scores
// measurably lower; both are compared over the same pixels.
#include <cmath>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "support/synthetic_plane.h"
#include "tessera/core/error.h"
#include "tessera/eval/view_evaluation.h"
#include "tessera/eval/view_render.h"

namespace tessera::eval {
namespace {

constexpr double kWallZ = 2.0;     // the wall is the plane z = 2 m of the world
constexpr double kHalfSide = 1.5;  // and spans [-1.5, 1.5] m in x and y
constexpr double kPeriod = 0.04;   // of the wall's colour stripes, metres

cv::Vec3b wallColour(double x, double y) {
  const double a = std::sin(2.0 * M_PI * x / kPeriod), b = std::cos(2.0 * M_PI * y / kPeriod);
  return {cv::saturate_cast<std::uint8_t>(128 + 90 * a),
          cv::saturate_cast<std::uint8_t>(128 + 60 * b),
          cv::saturate_cast<std::uint8_t>(128 + 45 * (a + b))};
}

// What a camera at T_W_C captures of the wall: exact depth and colour.
core::Frame captured(const core::Isometry& T_W_C, std::uint64_t index) {
  core::Frame frame =
      test::renderPlane(test::kinectIntrinsics(), T_W_C, Eigen::Vector3d(0, 0, 1), kWallZ);
  frame.index = index;
  frame.timestamp_ns = static_cast<std::int64_t>(index) * 33'000'000;
  const core::Intrinsics& k = frame.intrinsics;
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const Eigen::Vector3d ray =
          T_W_C.linear() * Eigen::Vector3d((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
      const double t = (kWallZ - T_W_C.translation().z()) / ray.z();
      const Eigen::Vector3d X = T_W_C.translation() + t * ray;
      frame.rgb.at<cv::Vec3b>(v, u) = wallColour(X.x(), X.y());
    }
  }
  return frame;
}

// The wall as a textured map (2 mm texels), its corners moved by `shift_x_m` along x.
RenderMesh wallMap(double shift_x_m) {
  constexpr int kTexels = 1500;  // 3 m at 2 mm
  RenderMesh mesh;
  mesh.textures.push_back({cv::Mat(kTexels, kTexels, CV_8UC4), false});  // clamped, as a bitmap
  for (int r = 0; r < kTexels; ++r) {
    for (int c = 0; c < kTexels; ++c) {
      // Texel centres; the image's first row is the top of the texture (t = 1, y = +1.5).
      const double x = -kHalfSide + (c + 0.5) * 2 * kHalfSide / kTexels;
      const double y = kHalfSide - (r + 0.5) * 2 * kHalfSide / kTexels;
      const cv::Vec3b rgb = wallColour(x, y);
      mesh.textures[0].rgba.at<cv::Vec4b>(r, c) = {rgb[0], rgb[1], rgb[2], 255};
    }
  }
  const auto corner = [&](double x, double y) {
    mesh.vertices.emplace_back(static_cast<float>(x + shift_x_m), static_cast<float>(y),
                               static_cast<float>(kWallZ));
  };
  corner(-kHalfSide, -kHalfSide), corner(kHalfSide, -kHalfSide);
  corner(kHalfSide, kHalfSide), corner(-kHalfSide, kHalfSide);
  const Eigen::Vector2f st[4] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  for (const Eigen::Vector3i& triangle : {Eigen::Vector3i(0, 1, 2), Eigen::Vector3i(0, 2, 3)}) {
    mesh.triangles.push_back(triangle);
    mesh.texture_of.push_back(0);
    for (int j = 0; j < 3; ++j) mesh.uvs.push_back(st[triangle[j]]);
  }
  return mesh;
}

// The same wall as two surfaces, "left" (x < 0) and "right", the right one moved by
// `shift_right_m` along x.
RenderMesh splitWallMap(double shift_right_m) {
  RenderMesh mesh = wallMap(0.0);
  mesh.vertices.clear(), mesh.triangles.clear(), mesh.texture_of.clear(), mesh.uvs.clear();
  mesh.surfaces = {"left", "right"};
  for (int side = 0; side < 2; ++side) {
    const double x0 = side == 0 ? -kHalfSide : 0.0, shift = side == 0 ? 0.0 : shift_right_m;
    const auto first = static_cast<int>(mesh.vertices.size());
    const float s0 = side == 0 ? 0.0F : 0.5F;
    const Eigen::Vector2f st[4] = {{s0, 0}, {s0 + 0.5F, 0}, {s0 + 0.5F, 1}, {s0, 1}};
    for (const auto& [x, y] : {std::pair{x0, -kHalfSide},
                               {x0 + kHalfSide, -kHalfSide},
                               {x0 + kHalfSide, kHalfSide},
                               {x0, kHalfSide}}) {
      mesh.vertices.emplace_back(static_cast<float>(x + shift), static_cast<float>(y),
                                 static_cast<float>(kWallZ));
    }
    for (const Eigen::Vector3i& corners : {Eigen::Vector3i(0, 1, 2), Eigen::Vector3i(0, 2, 3)}) {
      mesh.triangles.push_back(corners + Eigen::Vector3i::Constant(first));
      mesh.texture_of.push_back(0);
      mesh.surface_of.push_back(side);
      for (int j = 0; j < 3; ++j) mesh.uvs.push_back(st[corners[j]]);
    }
  }
  return mesh;
}

class VectorSource : public core::FrameSource {
 public:
  explicit VectorSource(std::vector<core::Frame> frames) : frames_(std::move(frames)) {}
  core::ReadResult read() override {
    if (next_ == frames_.size()) return {};
    return {core::ReadStatus::kFrame, frames_[next_++], ""};
  }
  std::string name() const override { return "wall views"; }
  std::optional<std::size_t> frameCount() const override { return frames_.size(); }

 private:
  std::vector<core::Frame> frames_;
  std::size_t next_ = 0;
};

struct WallViews {
  std::vector<core::Frame> frames;
  core::Trajectory poses;
};

WallViews wallViews() {
  WallViews views;
  for (int i = 0; i < 4; ++i) {
    core::Isometry T_W_C = core::Isometry::Identity();
    T_W_C.translation() = Eigen::Vector3d(0.15 * i - 0.2, 0.05 * i, 0.4 + 0.1 * i);
    T_W_C.linear() =
        Eigen::AngleAxisd(0.05 * (i - 1.5), Eigen::Vector3d::UnitY()).toRotationMatrix();
    views.frames.push_back(captured(T_W_C, static_cast<std::uint64_t>(i)));
    views.poses[views.frames.back().timestamp_ns] = T_W_C;
  }
  return views;
}

TEST(ViewEvaluation, AFaithfulMapScoresHighAndOneShiftedByACentimetreScoresLowerOnTheSamePixels) {
  const WallViews views = wallViews();
  const RenderMesh faithful = wallMap(0.0), shifted = wallMap(0.01);
  VectorSource source(views.frames);
  const ViewEvaluation evaluation =
      evaluateViews({{"faithful", &faithful}, {"shifted", &shifted}}, source, views.poses, {});
  ASSERT_EQ(evaluation.views.size(), 4u);
  const double faithful_psnr = *evaluation.meanPsnr(0, false);
  const double shifted_psnr = *evaluation.meanPsnr(1, false);
  EXPECT_GT(faithful_psnr, 32.0);  // texture resampling only
  // A quarter of a stripe period off: most of the contrast becomes error.
  EXPECT_LT(shifted_psnr, faithful_psnr - 10.0);

  // Swapped, the same pixels are compared, so each side keeps its score exactly.
  VectorSource again(views.frames);
  const ViewEvaluation swapped =
      evaluateViews({{"shifted", &shifted}, {"faithful", &faithful}}, again, views.poses, {});
  ASSERT_EQ(swapped.views.size(), evaluation.views.size());
  for (std::size_t i = 0; i < swapped.views.size(); ++i) {
    EXPECT_GT(evaluation.views[i].pixels, 200'000u);
    EXPECT_EQ(swapped.views[i].pixels, evaluation.views[i].pixels);
    EXPECT_DOUBLE_EQ(swapped.views[i].similarity[0].psnr_db,
                     evaluation.views[i].similarity[1].psnr_db);
    EXPECT_DOUBLE_EQ(swapped.views[i].similarity[1].psnr_db,
                     evaluation.views[i].similarity[0].psnr_db);
  }
  // Structure and detail say the same: the faithful map keeps the stripes where they were
  // seen, the shifted one puts them a quarter period off.
  const auto ssim = [&](std::size_t m) {
    return *evaluation.mean(m, false, &ImageSimilarity::ssim);
  };
  const auto detail = [&](std::size_t m) {
    return *evaluation.mean(m, false, &ImageSimilarity::detail);
  };
  EXPECT_GT(ssim(0), 0.95);
  EXPECT_LT(ssim(1), ssim(0) - 0.3);
  EXPECT_GT(detail(0), 0.95);
  // The stripes along y are not moved by a shift in x: their part of the detail stays.
  EXPECT_LT(detail(1), detail(0) - 0.3);
}

TEST(ViewEvaluation, TheSurfaceThatLosesAgainstTheBaselineIsNamedWithItsShareOfTheLoss) {
  const WallViews views = wallViews();
  const RenderMesh split = splitWallMap(0.01), faithful = wallMap(0.0);
  VectorSource source(views.frames);
  const ViewEvaluation evaluation =
      evaluateViews({{"split", &split}, {"faithful", &faithful}}, source, views.poses, {});
  ASSERT_EQ(evaluation.surfaces.size(), 2u);
  const SurfaceError& left = evaluation.surfaces[0];
  const SurfaceError& right = evaluation.surfaces[1];
  EXPECT_GT(left.pixels, 100'000u);
  EXPECT_GT(right.pixels, 100'000u);
  // Every compared training pixel belongs to one surface.
  EXPECT_EQ(left.pixels + right.pixels, evaluation.pixels(false));
  // The left half is the faithful map itself (split into other triangles); the right half a
  // quarter stripe off.
  EXPECT_NEAR(*left.psnr(0), *left.psnr(1), 0.01);  // the same texels, split differently
  EXPECT_GT(*left.psnr(0), 32.0);
  EXPECT_LT(*right.psnr(0), *right.psnr(1) - 10.0);

  const nlohmann::json worst = viewFigures(evaluation)["view_surfaces_worst"];
  ASSERT_EQ(worst.size(), 2u);
  EXPECT_EQ(worst[0]["surface"], "right");
  EXPECT_NEAR(worst[0]["share_of_loss"].get<double>(), 1.0, 1e-4);
  EXPECT_NEAR(worst[1]["share_of_loss"].get<double>(), 0.0, 1e-4);
}

// A camera sliding along x at 0.5 m/s whose colour image is taken 12 ms after its depth image
// (as a Kinect v1's unsynchronised cameras do): the colour was captured 6 mm further on.
TEST(ViewEvaluation, ViewsAreRenderedAtTheColourImagesTimeWhereTheSourceGivesIt) {
  constexpr std::int64_t kFrameNs = 33'000'000, kColourLagNs = 12'000'000;
  const auto poseAtTime = [](std::int64_t t_ns) {
    core::Isometry T_W_C = core::Isometry::Identity();
    T_W_C.translation() = Eigen::Vector3d(0.5 * static_cast<double>(t_ns) * 1e-9 - 0.1, 0.0, 0.6);
    return T_W_C;
  };
  std::vector<core::Frame> frames;
  core::Trajectory poses;  // at the depth images' times, as trajectory.txt holds them
  for (int i = 0; i < 6; ++i) {
    const std::int64_t t = i * kFrameNs;
    core::Frame frame = captured(poseAtTime(t), static_cast<std::uint64_t>(i));
    frame.rgb = captured(poseAtTime(t + kColourLagNs), static_cast<std::uint64_t>(i)).rgb;
    frame.colour_timestamp_ns = t + kColourLagNs;
    frames.push_back(std::move(frame));
    poses[t] = poseAtTime(t);
  }
  const RenderMesh faithful = wallMap(0.0);
  ViewEvaluationOptions options;
  VectorSource at_colour(frames);
  const ViewEvaluation colour = evaluateViews({{"faithful", &faithful}}, at_colour, poses, options);
  options.colour_time = false;
  VectorSource at_depth(frames);
  const ViewEvaluation depth = evaluateViews({{"faithful", &faithful}}, at_depth, poses, options);
  // The last frame's colour time lies past the trajectory's end: it is not scored.
  ASSERT_EQ(colour.views.size(), 5u);
  ASSERT_EQ(depth.views.size(), 6u);
  EXPECT_EQ(colour.poseTime(), "colour");
  EXPECT_EQ(depth.poseTime(), "depth");
  EXPECT_GT(*colour.meanPsnr(0, false), 32.0);  // interpolated poses are exact here
  EXPECT_LT(*depth.meanPsnr(0, false), *colour.meanPsnr(0, false) - 5.0);
  EXPECT_GT(*colour.mean(0, false, &ImageSimilarity::detail),
            *depth.mean(0, false, &ImageSimilarity::detail) + 0.1);
}

TEST(ViewEvaluation, HeldOutFramesAreScoredApartAndPixelsInFrontOfTheMapAreNotCompared) {
  WallViews views = wallViews();
  // Something stands 50 cm in front of the wall in the middle of the second view: the map is
  // not what that view saw there.
  core::Frame& blocked = views.frames[1];
  const cv::Rect box(200, 150, 200, 150);
  blocked.depth_mm(box).setTo(1000);
  blocked.rgb(box).setTo(cv::Scalar(255, 0, 0));
  const RenderMesh faithful = wallMap(0.0);
  VectorSource source(views.frames);
  ViewEvaluationOptions options;
  options.holdout_every = 2;  // frames 1 and 3
  const ViewEvaluation evaluation =
      evaluateViews({{"faithful", &faithful}}, source, views.poses, options);
  ASSERT_EQ(evaluation.viewCount(false), 2u);
  ASSERT_EQ(evaluation.viewCount(true), 2u);
  EXPECT_TRUE(evaluation.views[1].held_out);
  // The occluder's pixels (and a margin around them) are left out, so the score stays high.
  EXPECT_LT(evaluation.views[1].pixels, evaluation.views[3].pixels);
  EXPECT_GT(*evaluation.meanPsnr(0, true), 32.0);
  const nlohmann::json figures = viewFigures(evaluation);
  EXPECT_EQ(figures["view_frames_holdout"], 2);
  EXPECT_TRUE(figures["view_psnr_baseline_mean"].is_null());  // no second model
}

TEST(ViewRender, ReadsATexturedObjAndLeavesTransparentTexelsUncovered) {
  const auto dir = std::filesystem::temp_directory_path() / "tessera_view_render_test";
  std::filesystem::create_directories(dir);
  // A 1 m square at z = 2 whose texture is green, with its left half transparent.
  cv::Mat bgra(4, 4, CV_8UC4, cv::Scalar(0, 255, 0, 255));
  bgra(cv::Rect(0, 0, 2, 4)).setTo(cv::Scalar(0, 0, 0, 0));
  ASSERT_TRUE(cv::imwrite((dir / "square.png").string(), bgra));
  std::ofstream(dir / "square.mtl")
      << "newmtl square\nKd 1 1 1\nmap_Kd square.png\nmap_d square.png\n";
  std::ofstream(dir / "square.obj")
      << "mtllib square.mtl\nv -0.5 -0.5 2\nv 0.5 -0.5 2\nv 0.5 0.5 2\nv -0.5 0.5 2\n"
         "vt 0 1\nvt 1 1\nvt 1 0\nvt 0 0\no patch_7_v2\nusemtl square\nf 1/1 2/2 3/3 4/4\n";
  const RenderMesh mesh = readTexturedObj(dir / "square.obj");
  ASSERT_EQ(mesh.triangles.size(), 2u);
  const ViewImage view = renderView(mesh, test::kinectIntrinsics(), core::Isometry::Identity());
  // The square spans pixels 188-451 across at 2 m; its right half is green, its left half empty.
  EXPECT_NEAR(view.depth.at<float>(240, 400), 2.0F, 1e-4F);
  EXPECT_EQ(view.rgb.at<cv::Vec3b>(240, 400), cv::Vec3b(0, 255, 0));
  EXPECT_EQ(view.depth.at<float>(240, 250), 0.0F);
  EXPECT_EQ(view.depth.at<float>(20, 20), 0.0F);
  // Each drawn pixel names its surface, the OBJ's object.
  ASSERT_EQ(mesh.surfaces, std::vector<std::string>{"patch_7_v2"});
  EXPECT_EQ(view.surface.at<int>(240, 400), 0);
  EXPECT_EQ(view.surface.at<int>(240, 250), -1);
  EXPECT_THROW(readTexturedObj(dir / "missing.obj"), core::Error);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tessera::eval
