#include <fstream>
#include <random>
#include <set>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "support/test_data.h"
#include "tessera/core/error.h"
#include "tessera/drivers/oni/ground_truth_file.h"
#include "tessera/drivers/oni/oni_source.h"
#include "tessera/drivers/oni/oni_writer.h"
#include "tessera/drivers/synthetic/renderer.h"
#include "tessera/drivers/synthetic/scene_ground_truth.h"

namespace tessera::drivers::synthetic {
namespace {

namespace fs = std::filesystem;

fs::path officeScene() { return test::sourceDir() / "config/scenes/office.yaml"; }

double colourDistance(const cv::Vec3f& a, const cv::Vec3f& b) { return cv::norm(a - b); }

// colour(p + i a + j b) == colour(p) at seeded random points, and the texture does change
// under a shift by half a period (so the lattice is not trivially too large).
void expectExactLattice(const Texture& texture) {
  const auto lattice = texture.lattice();
  ASSERT_TRUE(lattice.has_value());
  std::mt19937 rng(99);
  std::uniform_real_distribution<double> coord(-3.0, 3.0);
  int changed_by_half = 0;
  for (int k = 0; k < 2000; ++k) {
    const Eigen::Vector2d p(coord(rng), coord(rng));
    const cv::Vec3f c = texture.colour(p.x(), p.y());
    for (const auto& [i, j] : {std::pair{1, 0}, {0, 1}, {2, -1}, {-3, 2}}) {
      const Eigen::Vector2d q = p + i * (*lattice)[0] + j * (*lattice)[1];
      ASSERT_LT(colourDistance(c, texture.colour(q.x(), q.y())), 1e-3)
          << texture.generator() << " at (" << p.transpose() << ") shifted by " << i << "," << j;
    }
    const Eigen::Vector2d half = p + (*lattice)[0] / 2;
    changed_by_half += colourDistance(c, texture.colour(half.x(), half.y())) > 1.0;
  }
  EXPECT_GT(changed_by_half, 500) << texture.generator();
}

TEST(SyntheticTextures, PeriodicGeneratorsRepeatExactlyOnTheirLattice) {
  const Scene scene = loadScene(officeScene());
  for (const char* id : {"brick", "floor_tiles", "cobbles"}) {
    SCOPED_TRACE(id);
    expectExactLattice(*scene.textures.at(id));
  }
  // Running bond: one lattice vector is the half-brick shift up one course.
  const auto brick = *scene.textures.at("brick")->lattice();
  EXPECT_NEAR(brick[1].x(), (0.215 + 0.01) / 2, 1e-12);
  EXPECT_NEAR(brick[1].y(), 0.065 + 0.01, 1e-12);
  EXPECT_FALSE(scene.textures.at("poster_a")->lattice().has_value());
  EXPECT_FALSE(scene.textures.at("plaster")->lattice().has_value());
}

TEST(SyntheticTextures, ImageTexturesSampleTheirPixelsAndTileExactly) {
  TESSERA_REQUIRE_SHARED("textures/gimp_patterns");
  const fs::path image = test::sharedData() / "textures/gimp_patterns/png/Fabric__burlap.png";
  const fs::path dir = test::freshTempDir();
  std::ofstream(dir / "scene.yaml")
      << "textures:\n"
      << "  - {id: cloth, generator: image, image: " << image.string()
      << ", width_m: 0.192, tile: true}\n"
      << "camera: {waypoints: [{position: [0, 0, 1], look_at: [1, 0, 1]}]}\n";
  const Scene scene = loadScene(dir / "scene.yaml");
  const Texture& cloth = *scene.textures.at("cloth");
  expectExactLattice(cloth);
  EXPECT_NEAR((*cloth.lattice())[0].x(), 0.192, 1e-12);  // 96 pixels of 2 mm
  // Texel centres give the pixels themselves; image row 0 is the top (largest t).
  cv::Mat bgr = cv::imread(image.string(), cv::IMREAD_COLOR);
  const double texel = 0.192 / 96;
  for (const auto& [row, col] : {std::pair{0, 0}, {10, 70}, {95, 3}}) {
    const cv::Vec3b pixel = bgr.at<cv::Vec3b>(row, col);
    const cv::Vec3f c = cloth.colour((col + 0.5) * texel, (95 - row + 0.5) * texel);
    EXPECT_NEAR(c[0], pixel[2], 1e-3);  // R
    EXPECT_NEAR(c[2], pixel[0], 1e-3);  // B
  }
}

// Back-projects every valid depth pixel at the ground-truth pose and measures its distance to
// the ground-truth plane the renderer says it hit.
struct PlaneResiduals {
  std::size_t pixels = 0;
  std::size_t within = 0;
  double worst_m = 0.0;
};

PlaneResiduals planeResiduals(const Scene& scene, int frame_index, const SensorProfile& sensor,
                              double sigmas) {
  const core::Isometry T_W_C = scene.cameraPose(frame_index);
  const CleanView view = renderClean(scene, sensor.intrinsics, T_W_C, 1);
  cv::Mat depth_mm, rgb;
  applySensor(sensor, view, 7, depth_mm, rgb);
  const core::Intrinsics& k = sensor.intrinsics;
  const double bf = sensor.baseline_m * sensor.disparity_focal_px;
  PlaneResiduals r;
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const int id = view.surface_id.at<int>(v, u);
      const double z = depth_mm.at<std::uint16_t>(v, u) * 1e-3;
      if (id < 0 || z <= 0.0) continue;
      const ScenePlane& plane = scene.planes[static_cast<std::size_t>(id)];
      const Eigen::Vector3d X =
          T_W_C * Eigen::Vector3d((u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z);
      const double distance = std::abs(plane.normal.dot(X) - plane.offset());
      // Errors are along z, so a point moves |ray| times as far: noise, half a disparity step
      // and half a millimetre of rounding.
      const double step =
          sensor.disparity_quantisation ? z * z * sensor.disparity_step_px / bf : 0.0;
      const double ray = Eigen::Vector3d((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0).norm();
      const double bound = ray * (sigmas * depthNoiseSigma(sensor, z) + step / 2 + 0.0005) + 1e-9;
      ++r.pixels;
      r.within += distance <= bound;
      r.worst_m = std::max(r.worst_m, distance);
    }
  }
  return r;
}

TEST(SyntheticRenderer, DepthBackProjectsOntoTheGroundTruthPlanes) {
  const Scene scene = loadScene(officeScene());
  // Noise-free sensor: only millimetre rounding separates a pixel from its plane.
  const PlaneResiduals ideal = planeResiduals(scene, 100, SensorProfile::named("ideal"), 0.0);
  EXPECT_GT(ideal.pixels, 200000u);
  EXPECT_EQ(ideal.within, ideal.pixels) << "worst " << ideal.worst_m << " m";
  // Kinect v1 model: 99% within 3 sigma of the noise model plus half a disparity step.
  const PlaneResiduals kinect = planeResiduals(scene, 100, SensorProfile::named("kinect_v1"), 3.0);
  EXPECT_GT(kinect.pixels, 150000u);
  EXPECT_GT(static_cast<double>(kinect.within) / static_cast<double>(kinect.pixels), 0.99);
}

TEST(SyntheticRenderer, IsDeterministicForTheSeed) {
  SyntheticSource a(officeScene()), b(officeScene());
  const core::ReadResult first = a.read(), second = b.read();
  ASSERT_EQ(first.status, core::ReadStatus::kFrame);
  EXPECT_EQ(cv::norm(first.frame.depth_mm, second.frame.depth_mm, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(first.frame.rgb, second.frame.rgb, cv::NORM_INF), 0.0);
  EXPECT_TRUE(first.frame.T_W_C_gt->isApprox(*second.frame.T_W_C_gt));
  EXPECT_EQ(a.frameCount(), 320u);
}

TEST(SyntheticScene, GroundTruthDescribesPlanesAndLattices) {
  const Scene scene = loadScene(officeScene());
  const nlohmann::json gt = sceneGroundTruth(scene);
  std::set<std::string> ids;
  for (const auto& plane : gt["planes"]) {
    ids.insert(plane["id"].get<std::string>());
    const Eigen::Vector3d n(plane["normal"][0], plane["normal"][1], plane["normal"][2]);
    EXPECT_NEAR(n.norm(), 1.0, 1e-12);
    for (const auto& corner : plane["polygon_world"]) {  // every corner lies on its plane
      const Eigen::Vector3d X(corner[0], corner[1], corner[2]);
      EXPECT_NEAR(n.dot(X), plane["offset_m"].get<double>(), 1e-9);
    }
  }
  EXPECT_TRUE(ids.contains("table_1.top") && ids.contains("table_2.top"));
  EXPECT_EQ(ids.size(), gt["planes"].size()) << "plane ids must be unique";
  // Box faces point out of the box: the table top's normal is +z.
  for (const auto& plane : gt["planes"]) {
    if (plane["id"] == "table_1.top") {
      EXPECT_DOUBLE_EQ(plane["normal"][2].get<double>(), 1.0);
    }
    if (plane["id"] == "cabinet.top") {
      // Tiles at half scale, turned 30 degrees: the lattice on the plane is 0.3 m long.
      const Eigen::Vector2d a(plane["lattice_uv_m"][0][0], plane["lattice_uv_m"][0][1]);
      EXPECT_NEAR(a.norm(), 0.5 * 0.6, 1e-12);
    }
  }
}

TEST(SyntheticScene, MistakesAreNamedWithTheFile) {
  const fs::path dir = test::freshTempDir();
  const auto expectError = [&](const std::string& yaml, const std::string& expected) {
    std::ofstream(dir / "scene.yaml") << yaml;
    try {
      loadScene(dir / "scene.yaml");
      ADD_FAILURE() << "expected an error for: " << yaml;
    } catch (const core::ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("scene.yaml"), std::string::npos) << e.what();
    }
  };
  const std::string camera = "camera: {waypoints: [{position: [0, 0, 1], look_at: [1, 0, 1]}]}\n";
  expectError("textures: [{id: t, generator: marble}]\n" + camera, "marble");
  expectError(
      "planes: [{id: p, texture: none, origin: [0,0,0], u_axis: [1,0,0], v_axis: [0,1,0], "
      "polygon: [[0,0],[1,0],[1,1]]}]\n" +
          camera,
      "'none'");
  expectError("textures: [{id: t, generator: brick, brick_widht_m: 0.2}]\n" + camera,
              "textures[0].brick_widht_m");
  expectError("sensor: kinect_v3\n" + camera, "kinect_v3");
  expectError("frames: 3\n", "waypoints");
}

TEST(SyntheticRecording, RoundTripsThroughOpenNi2BitExact) {
  SyntheticSource source(officeScene());
  std::vector<core::Frame> frames;
  for (int i = 0; i < 3; ++i) frames.push_back(source.read().frame);
  const fs::path path = test::freshTempDir() / "office3.oni";
  oni::OniWriterOptions options;
  options.colour_codec = oni::ColourCodec::kNone;
  {
    oni::OniWriter writer(path, frames[0].intrinsics, frames[0].rgb.size(), options);
    for (const auto& frame : frames) writer.write(frame);
    writer.close();
  }
  oni::OniSource playback(path);
  for (const auto& frame : frames) {
    const core::ReadResult back = playback.read();
    ASSERT_EQ(back.status, core::ReadStatus::kFrame);
    EXPECT_EQ(cv::norm(back.frame.depth_mm, frame.depth_mm, cv::NORM_INF), 0.0);
    EXPECT_EQ(cv::norm(back.frame.rgb, frame.rgb, cv::NORM_INF), 0.0);
    EXPECT_EQ(back.frame.timestamp_ns, frame.timestamp_ns);
  }
  EXPECT_EQ(playback.read().status, core::ReadStatus::kEndOfData);
}

TEST(SyntheticRecording, UnregisteredColourKeepsItsCameraThroughTheRecording) {
  // The office scene with its colour camera 2.5 cm beside the depth camera.
  const fs::path dir = test::freshTempDir();
  std::ifstream office(officeScene());
  std::ofstream(dir / "office_unregistered.yaml") << "colour_registered: false\n" << office.rdbuf();
  SyntheticSource source(dir / "office_unregistered.yaml");
  const core::Frame frame = source.read().frame;
  ASSERT_TRUE(frame.colour_camera.has_value());
  EXPECT_NEAR(frame.colour_camera->T_RGB_D.translation().x(), -0.025, 1e-12);

  const fs::path path = dir / "unregistered.oni";
  oni::GroundTruthFile ground_truth;
  ground_truth.setIntrinsics(frame.intrinsics);
  ground_truth.setColourCamera(*frame.colour_camera);
  ground_truth.addFrame(frame);
  {
    oni::OniWriter writer(path, frame.intrinsics, frame.rgb.size());
    writer.write(frame);
    writer.close();
  }
  ground_truth.write(oni::groundTruthPath(path));
  oni::OniSource playback(path);
  const core::ReadResult back = playback.read();
  ASSERT_EQ(back.status, core::ReadStatus::kFrame);
  ASSERT_TRUE(back.frame.colour_camera.has_value());
  EXPECT_TRUE(back.frame.colour_camera->T_RGB_D.isApprox(frame.colour_camera->T_RGB_D, 1e-9));
}

}  // namespace
}  // namespace tessera::drivers::synthetic
