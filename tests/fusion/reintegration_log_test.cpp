// The TSDF fused again at corrected poses: a drifted half of the views, moved back by its
// keyframe's correction, lands on the surface the other half saw; a log that cannot write says
// so and refuses to rebuild.
#include <cmath>
#include <fstream>
#include <optional>

#include <gtest/gtest.h>

#include "support/synthetic_plane.h"
#include "support/test_data.h"
#include "tessera/core/error.h"
#include "tessera/fusion/reintegration_log.h"

namespace tessera::fusion {
namespace {

// Six views of a tilted plane about 1.5 m ahead; views 3 to 5 are tracked with `drift`
// (tracked = drift * true) and follow keyframe 3, views 0 to 2 keyframe 0. Returns the
// largest distance of the rebuilt surface from the plane for the given correction of keyframe 3
// (none: views 3 to 5 are left out).
double worstDistanceFromPlane(const core::Isometry& drift,
                              const std::optional<core::Isometry>& correction_3) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.15, -0.25, -1.0).normalized();
  const double d = n.dot(Eigen::Vector3d(0.0, 0.0, 1.5137));
  const core::Intrinsics k = test::kinectIntrinsics();
  ReintegrationLog log(test::freshTempDir() / "frames", 2);
  for (int i = 0; i < 6; ++i) {
    core::Isometry T_W_C = core::Isometry::Identity();
    T_W_C.translation() = Eigen::Vector3d(0.05 * i, -0.02 * i, 0.01 * i);
    core::Frame frame = test::renderPlane(k, T_W_C, n, d);
    frame.index = static_cast<std::uint64_t>(i);
    const std::int64_t keyframe = i < 3 ? 0 : 3;
    log.keep(frame, keyframe == 3 ? core::Isometry(drift * T_W_C) : T_W_C, keyframe);
  }
  EXPECT_TRUE(log.usable()) << log.error();
  EXPECT_EQ(log.size(), 6u);
  EXPECT_GT(log.diskBytes(), 0u);
  const SurfaceMesh mesh =
      log.rebuild(TsdfConfig{}, [&](std::int64_t keyframe) -> std::optional<core::Isometry> {
        return keyframe == 3 ? correction_3 : core::Isometry::Identity();
      });
  EXPECT_GT(mesh.vertices.size(), 5000u);  // three views or six
  double worst = 0.0;
  for (const Eigen::Vector3d& X : mesh.vertices) worst = std::max(worst, std::abs(n.dot(X) - d));
  return worst;
}

TEST(ReintegrationLog, ADriftedHalfMovedByItsCorrectionLandsOnTheSurface) {
  // 8 cm and 3 degrees of drift: fused as tracked, the plane is doubled.
  const core::Isometry drift = core::Isometry(Eigen::Translation3d(0.02, -0.03, 0.08)) *
                               Eigen::AngleAxisd(3.0 * M_PI / 180.0, Eigen::Vector3d::UnitX());
  EXPECT_GT(worstDistanceFromPlane(drift, core::Isometry::Identity()), 0.05);
  // Loop closure's correction of keyframe 3 (corrected * tracked^-1) undoes the drift.
  EXPECT_LE(worstDistanceFromPlane(drift, drift.inverse()), TsdfConfig{}.voxel_size_m);
  // Keyframe 3's segment never joined the map: its views are left out, not fused as tracked.
  EXPECT_LE(worstDistanceFromPlane(drift, std::nullopt), TsdfConfig{}.voxel_size_m);
}

TEST(ReintegrationLog, AFolderThatCannotBeWrittenTurnsTheLogOffWithOneClearError) {
  // A file where the folder should be: nothing can be written under it.
  const auto blocked = test::freshTempDir() / "not_a_folder";
  std::ofstream(blocked) << "x";
  ReintegrationLog log(blocked / "frames", 2);
  const core::Intrinsics k = test::kinectIntrinsics();
  log.keep(test::renderPlane(k, core::Isometry::Identity(), Eigen::Vector3d(0, 0, -1), -1.5),
           core::Isometry::Identity(), 0);
  EXPECT_FALSE(log.usable());
  EXPECT_EQ(log.size(), 0u);
  EXPECT_NE(log.error().find("not_a_folder"), std::string::npos) << log.error();
  EXPECT_THROW(log.rebuild(TsdfConfig{}, [](std::int64_t) { return core::Isometry::Identity(); }),
               core::Error);
}

}  // namespace
}  // namespace tessera::fusion
