// The map after loop closure, on a test-sized loop: two passes through the office's first 1.4 m
// of path, the second fed as tracked with 12 cm and 2 degrees of drift. The planes the drifted
// pass found double the first pass's; the loop graph's corrections, followed as the keyframes
// come (as the plane stage does), bring them back onto them and merge them.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <gtest/gtest.h>

#include "support/keyframe_record.h"
#include "support/synthetic_office.h"
#include "support/test_data.h"
#include "tessera/drivers/synthetic/scene.h"
#include "tessera/loop/loop_graph.h"
#include "tessera/planes/patch_map.h"
#include "tessera/planes/plane_detector.h"

namespace tessera::loop {
namespace {

namespace synthetic = drivers::synthetic;

struct PlaneFigure {
  Eigen::Vector3d normal;
  double offset = 0.0;
};

// One entry per plane of at least 0.3 m^2 in all its tiles.
std::vector<PlaneFigure> planesOf(const planes::PatchMap& map) {
  std::vector<PlaneFigure> out;
  for (const auto& [id, plane] : map.planes()) {
    double area = 0.0;
    for (const auto& [key, tile] : plane.tiles) area += map.areaM2(*map.find(tile));
    if (area >= 0.3) out.push_back({plane.geometry->normal, plane.geometry->offset});
  }
  return out;
}

bool hasPlaneNear(const std::vector<PlaneFigure>& planes, const PlaneFigure& p, double offset_m,
                  double angle_deg) {
  for (const PlaneFigure& q : planes) {
    const double cos_angle = std::min(1.0, q.normal.dot(p.normal));
    if (std::acos(cos_angle) * 180.0 / M_PI <= angle_deg &&
        std::abs(q.offset - p.offset) <= offset_m) {
      return true;
    }
  }
  return false;
}

TEST(LoopMap, ADriftedSecondPassMergesIntoTheFirstPassPlanesOnceTheLoopCloses) {
  const synthetic::Scene office =
      synthetic::loadScene(test::sourceDir() / "config/scenes/office.yaml");
  const core::Isometry drift = core::Isometry(Eigen::Translation3d(0.10, -0.05, 0.04)) *
                               Eigen::AngleAxisd(2.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ());
  LoopConfig config;
  config.min_travel_m = 1.0;  // the second pass starts 1.4 m of path after the first
  LoopGraph graph(config);
  planes::PatchMapConfig patches;
  patches.stable_frames = 2;
  patches.out_of_view_frames = 3;
  planes::PatchMap followed(patches), unfollowed(patches);
  const planes::PlaneDetector detector{planes::PlaneDetectorConfig{}};

  std::size_t followed_generation = 0, merges = 0;
  MapCorrection correction;
  std::vector<PlaneFigure> first_pass;
  long index = 0;
  for (int pass = 0; pass < 2; ++pass) {
    for (int frame = 0; frame <= 100; frame += 20, ++index) {
      const core::Isometry truth = office.cameraPose(frame);
      const core::Isometry tracked = pass == 0 ? truth : core::Isometry(drift * truth);
      const core::Frame image = test::officeFrameAt(office, truth, 1000 * pass + frame);
      const std::int64_t keyframe_ns = index * 1'000'000'000LL;
      graph.add(test::keyframeRecordOf(image, tracked, keyframe_ns));
      if (graph.stats().optimisations != followed_generation) {
        followed_generation = graph.stats().optimisations;
        correction = graph.correction();
        followed.followCorrection([&](std::int64_t t) { return correction.at(t); });
        merges += followed.mergeCoinciding();
      }
      const planes::PlaneDetection detection = detector.detect(image);
      for (planes::PatchMap* map : {&followed, &unfollowed}) {
        const core::Isometry motion =
            map == &followed ? correction.at(keyframe_ns) : core::Isometry::Identity();
        auto observations = planes::observationsOf(image, detection, motion * tracked);
        for (auto& observation : observations) {
          observation.keyframe_ns = keyframe_ns;
          observation.loop_motion = motion;
        }
        map->add(observations);
        map->endFrame(index);
      }
    }
    if (pass == 0) first_pass = planesOf(followed);
  }
  graph.finish();
  if (graph.stats().optimisations != followed_generation) {
    correction = graph.correction();
    followed.followCorrection([&](std::int64_t t) { return correction.at(t); });
    merges += followed.mergeCoinciding();
  }

  ASSERT_GE(first_pass.size(), 3u);
  ASSERT_GE(graph.stats().loop_closures, 2u);
  // Without following the correction the drifted pass doubles planes.
  const std::vector<PlaneFigure> doubled = planesOf(unfollowed);
  EXPECT_GT(doubled.size(), first_pass.size());
  // Following it, every plane lies where the first pass put one: nothing doubled.
  EXPECT_GE(merges, 1u);
  const std::vector<PlaneFigure> after = planesOf(followed);
  EXPECT_EQ(after.size(), first_pass.size());
  for (const PlaneFigure& p : after) {
    EXPECT_TRUE(hasPlaneNear(first_pass, p, 0.02, 1.5))
        << "a plane n = " << p.normal.transpose() << ", d = " << p.offset
        << " has no first-pass plane within 2 cm and 1.5 degrees";
  }
}

}  // namespace
}  // namespace tessera::loop
