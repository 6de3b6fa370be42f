#include <algorithm>
#include <array>
#include <fstream>
#include <iterator>
#include <map>

#include <gtest/gtest.h>

#include "support/synthetic_plane.h"
#include "support/test_data.h"
#include "tessera/core/error.h"
#include "tessera/fusion/tsdf_map.h"

namespace tessera::fusion {
namespace {

// A camera at `position` looking along world +z, turned by `yaw_rad` about the world y axis.
core::Isometry cameraAt(const Eigen::Vector3d& position, double yaw_rad) {
  core::Isometry T_W_C = core::Isometry::Identity();
  T_W_C.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitY()).toRotationMatrix();
  T_W_C.translation() = position;
  return T_W_C;
}

// Fuses six views of a tilted plane and checks the surface against it.
void expectPlaneWithinOneVoxel(const TsdfConfig& config) {
  TsdfMap map(config);
  EXPECT_EQ(map.memoryBytes(), 0u);

  // A tilted plane about 1.5 m ahead; its offset is deliberately off the voxel lattice.
  const Eigen::Vector3d n = Eigen::Vector3d(0.15, -0.25, -1.0).normalized();
  const double d = n.dot(Eigen::Vector3d(0.0, 0.0, 1.5137));
  const core::Intrinsics k = test::kinectIntrinsics();
  for (int i = 0; i < 6; ++i) {
    const core::Isometry T_W_C = cameraAt({0.05 * i, -0.02 * i, 0.01 * i}, 0.03 * i);
    core::Frame frame = test::renderPlane(k, T_W_C, n, d);
    frame.index = static_cast<std::uint64_t>(i);
    map.integrate(frame, T_W_C);
  }
  EXPECT_GT(map.memoryBytes(), 0u);

  const SurfaceMesh mesh = map.extractMesh();
  ASSERT_GT(mesh.vertices.size(), 10000u);
  ASSERT_EQ(mesh.colors.size(), mesh.vertices.size());
  double worst = 0.0;
  Eigen::Vector3d lo = mesh.vertices.front(), hi = mesh.vertices.front();
  for (const Eigen::Vector3d& X : mesh.vertices) {
    worst = std::max(worst, std::abs(n.dot(X) - d));
    lo = lo.cwiseMin(X);
    hi = hi.cwiseMax(X);
  }
  EXPECT_LE(worst, config.voxel_size_m) << "surface vertex farther than one voxel from the plane";
  // The plane fills the view: at 1.5 m a 640x480 Kinect sees about 1.8 m x 1.4 m.
  EXPECT_GT(hi.x() - lo.x(), 1.5);
  EXPECT_GT(hi.y() - lo.y(), 1.1);
}

TEST(TsdfMap, SurfaceOfASyntheticPlaneLiesWithinOneVoxelOfTheTruth) {
  expectPlaneWithinOneVoxel(TsdfConfig{});  // 2 cm voxels, depth at half resolution
}

TEST(TsdfMap, FullAndHalfResolutionIntegrationKeepOneCentimetreVoxelsOnThePlane) {
  for (const int scale : {1, 2}) {
    SCOPED_TRACE(scale);
    TsdfConfig config;
    config.voxel_size_m = 0.01;
    config.truncation_m = 0.04;
    config.integration_scale = scale;
    expectPlaneWithinOneVoxel(config);
  }
}

TEST(TsdfMap, BlocksFarBehindTheCameraAreFreed) {
  TsdfMap map(TsdfConfig{});
  const core::Intrinsics k = test::kinectIntrinsics();
  const Eigen::Vector3d n(0, 0, -1);
  const core::Isometry T_W_C = core::Isometry::Identity();  // looking along world +z
  map.integrate(test::renderPlane(k, T_W_C, n, n.dot(Eigen::Vector3d(0, 0, 1.5))), T_W_C);
  const std::size_t blocks = map.blockCount();
  ASSERT_GT(blocks, 0u);
  const std::size_t bytes_per_block = map.memoryBytes() / blocks;
  const std::size_t triangles = map.extractMesh().triangles.size();
  ASSERT_GT(triangles, 1000u);

  // The plane is 1.5 m ahead: nothing is behind the camera.
  EXPECT_EQ(map.releaseBlocksBehind(T_W_C, 0.5), 0u);
  // Driven on to 3 m along +z, still looking along +z, the plane is 1.5 m behind: freed only
  // when the distance allows it.
  core::Isometry past = core::Isometry::Identity();
  past.translation() = Eigen::Vector3d(0, 0, 3.0);
  EXPECT_EQ(map.releaseBlocksBehind(past, 3.0), 0u);
  EXPECT_EQ(map.blockCount(), blocks);
  // From 1.5 m the plane's centre blocks stay, its far corners (up to ~1.9 m) go.
  const std::size_t released = map.releaseBlocksBehind(past, 1.7);
  EXPECT_GT(released, 0u);
  EXPECT_LT(released, blocks);
  EXPECT_EQ(map.blockCount(), blocks - released);
  EXPECT_EQ(map.memoryBytes(), (blocks - released) * bytes_per_block + map.releasedSurfaceBytes());
  EXPECT_EQ(map.releaseBlocksBehind(past, 0.5), blocks - released);
  // The released blocks' surface stays in the mesh (less the one-voxel seams between blocks
  // released at different times), at a small part of their voxels' bytes.
  EXPECT_EQ(map.blockCount(), 0u);
  EXPECT_EQ(map.memoryBytes(), map.releasedSurfaceBytes());
  EXPECT_LT(map.releasedSurfaceBytes(), blocks * bytes_per_block / 5);
  EXPECT_GT(map.extractMesh().triangles.size(), triangles * 9 / 10);
  EXPECT_LE(map.extractMesh().triangles.size(), triangles);
}

// A robot walking past the same wall lap after lap: the wall is fused, left behind and
// released, then fused again on the next lap. What the map keeps of it stays one lap's.
TEST(TsdfMap, AWallReleasedLapAfterLapIsKeptOnce) {
  TsdfMap map(TsdfConfig{});
  const core::Intrinsics k = test::kinectIntrinsics();
  const Eigen::Vector3d n(0, 0, -1);
  const double d = n.dot(Eigen::Vector3d(0, 0, 1.5));
  core::Isometry past = core::Isometry::Identity();
  past.translation() = Eigen::Vector3d(0, 0, 4.0);
  std::size_t pieces = 0, bytes = 0, triangles = 0;
  for (int lap = 0; lap < 4; ++lap) {
    SCOPED_TRACE(lap);
    const core::Isometry T_W_C = core::Isometry::Identity();
    map.integrate(test::renderPlane(k, T_W_C, n, d), T_W_C);
    ASSERT_GT(map.releaseBlocksBehind(past, 0.5), 0u);
    EXPECT_EQ(map.blockCount(), 0u);
    if (lap == 0) {
      pieces = map.releasedPieces();
      bytes = map.releasedSurfaceBytes();
      triangles = map.extractMesh().triangles.size();
      ASSERT_GT(triangles, 1000u);
    }
    // The same wall: the same pieces, not one more copy a lap.
    EXPECT_EQ(map.releasedPieces(), pieces);
    EXPECT_EQ(map.releasedSurfaceBytes(), bytes);
    const SurfaceMesh mesh = map.extractMesh();
    EXPECT_EQ(mesh.triangles.size(), triangles);
    // The bytes kept as pieces are replaced are those of the pieces (nothing is live here):
    // float positions, 8-bit colours, triangles.
    EXPECT_EQ(bytes, mesh.vertices.size() * (sizeof(Eigen::Vector3f) + 3) +
                         mesh.triangles.size() * sizeof(Eigen::Vector3i));
  }
}

// Released blocks keep their surface compactly (float positions, 8-bit colours) but the same:
// released all at once, the mesh has the live mesh's triangles, area and colour.
TEST(TsdfMap, ReleasedSurfaceIsTheLiveSurfaceToFloatAndByteRounding) {
  TsdfMap map(TsdfConfig{});
  const core::Intrinsics k = test::kinectIntrinsics();
  const Eigen::Vector3d n = Eigen::Vector3d(0.2, -0.1, -1.0).normalized();
  const core::Isometry T_W_C = core::Isometry::Identity();
  core::Frame frame = test::renderPlane(k, T_W_C, n, n.dot(Eigen::Vector3d(0, 0, 1.5)));
  // A colour gradient, so that the colours differ from vertex to vertex.
  for (int v = 0; v < frame.rgb.rows; ++v) {
    for (int u = 0; u < frame.rgb.cols; ++u) {
      frame.rgb.at<cv::Vec3b>(v, u) =
          cv::Vec3b(static_cast<std::uint8_t>(u * 255 / frame.rgb.cols),
                    static_cast<std::uint8_t>(v * 255 / frame.rgb.rows), 90);
    }
  }
  map.integrate(frame, T_W_C);
  const auto area = [](const SurfaceMesh& mesh) {
    double sum = 0.0;
    for (const Eigen::Vector3i& t : mesh.triangles) {
      sum += 0.5 * (mesh.vertices[t[1]] - mesh.vertices[t[0]])
                       .cross(mesh.vertices[t[2]] - mesh.vertices[t[0]])
                       .norm();
    }
    return sum;
  };
  const SurfaceMesh live = map.extractMesh();
  ASSERT_GT(live.triangles.size(), 1000u);
  core::Isometry past = core::Isometry::Identity();
  past.translation() = Eigen::Vector3d(0, 0, 4.0);
  const std::size_t blocks = map.blockCount();
  ASSERT_EQ(map.releaseBlocksBehind(past, 0.5), blocks);
  const SurfaceMesh released = map.extractMesh();
  EXPECT_EQ(released.triangles.size(), live.triangles.size());
  EXPECT_NEAR(area(released), area(live), 1e-5 * area(live));
  // Each kept vertex is a live vertex rounded to float, its colour rounded to 8 bits.
  std::map<std::array<float, 3>, Eigen::Vector3d> live_colour;
  for (std::size_t i = 0; i < live.vertices.size(); ++i) {
    const Eigen::Vector3f p = live.vertices[i].cast<float>();
    live_colour[{p.x(), p.y(), p.z()}] = live.colors[i];
  }
  double worst = 0.0;
  for (std::size_t i = 0; i < released.vertices.size(); ++i) {
    const Eigen::Vector3f p = released.vertices[i].cast<float>();
    const auto it = live_colour.find({p.x(), p.y(), p.z()});
    ASSERT_NE(it, live_colour.end()) << "vertex " << i << " is not a live vertex";
    worst = std::max(worst, (released.colors[i] - it->second).cwiseAbs().maxCoeff());
  }
  EXPECT_LE(worst, 0.5 / 255.0 + 1e-9);
}

TEST(TsdfMap, DepthOutsideTheConfiguredRangeIsIgnored) {
  TsdfConfig config;
  config.max_depth_m = 1.0;  // the plane at 1.5 m is beyond it
  TsdfMap map(config);
  const core::Intrinsics k = test::kinectIntrinsics();
  const Eigen::Vector3d n(0, 0, -1);
  const core::Isometry T_W_C = core::Isometry::Identity();
  map.integrate(test::renderPlane(k, T_W_C, n, n.dot(Eigen::Vector3d(0, 0, 1.5137))), T_W_C);
  EXPECT_TRUE(map.extractMesh().vertices.empty());
}

TEST(TsdfMap, FrameWhoseSizeDisagreesWithItsIntrinsicsIsRejected) {
  TsdfMap map(TsdfConfig{});
  core::Frame frame = test::renderPlane(test::kinectIntrinsics(), core::Isometry::Identity(),
                                        Eigen::Vector3d(0, 0, -1), -1.5);
  frame.intrinsics.width = 320;
  EXPECT_THROW(map.integrate(frame, core::Isometry::Identity()), core::Error);
}

TEST(TsdfMap, AllInvalidDepthAddsNothing) {
  TsdfMap map(TsdfConfig{});
  core::Frame frame = test::renderPlane(test::kinectIntrinsics(), core::Isometry::Identity(),
                                        Eigen::Vector3d(0, 0, -1), -1.5);
  frame.depth_mm.setTo(0);
  map.integrate(frame, core::Isometry::Identity());
  EXPECT_TRUE(map.extractMesh().vertices.empty());
}

}  // namespace
}  // namespace tessera::fusion

// A run that fused nothing (a live device lost before its first frame) still writes a valid,
// empty mesh file rather than failing at export.
TEST(TsdfMap, AnEmptyMeshIsWrittenAsAValidEmptyPly) {
  const auto path = tessera::test::freshTempDir() / "empty.ply";
  tessera::fusion::writePly(tessera::fusion::SurfaceMesh{}, path);
  std::ifstream in(path);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(text.rfind("ply\n", 0), 0u);
  EXPECT_NE(text.find("element vertex 0\n"), std::string::npos);
  EXPECT_NE(text.find("element face 0\n"), std::string::npos);
  EXPECT_NE(text.find("end_header\n"), std::string::npos);
}
