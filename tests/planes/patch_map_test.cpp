#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <tuple>

#include <gtest/gtest.h>

#include "support/synthetic_plane.h"
#include "support/test_data.h"
#include "tessera/planes/patch_map.h"

namespace tessera::planes {
namespace {

// Points on the plane z = height + tilt * x over [x0, x1] x [y0, y1], 1 cm apart, with
// seeded Gaussian noise of sigma_m along z.
PlaneObservation strip(double x0, double x1, double y0, double y1, double height,
                       double sigma_m = 0.0, double tilt = 0.0, unsigned seed = 1) {
  std::mt19937 random(seed);
  std::normal_distribution<double> noise(0.0, sigma_m);
  PlaneObservation observation;
  for (double x = x0; x <= x1; x += 0.01) {
    for (double y = y0; y <= y1; y += 0.01) {
      observation.points_W.emplace_back(x, y,
                                        height + tilt * x + (sigma_m > 0 ? noise(random) : 0.0));
    }
  }
  return observation;
}

TEST(PatchMap, TheSamePlaneSeenAgainGrowsOnePatch) {
  PatchMap map(PatchMapConfig{});
  map.add({strip(0.0, 1.0, 0.0, 1.0, 0.75, 0.005, 0.0, 1)});
  map.add({strip(0.8, 1.8, 0.0, 1.0, 0.75, 0.005, 0.0, 2)});  // overlaps and extends it
  ASSERT_EQ(map.patches().size(), 1u);
  const Patch& patch = map.patches().front();
  EXPECT_NEAR(std::abs(patch.normal().z()), 1.0, 1e-4);
  EXPECT_NEAR(std::abs(patch.offset()), 0.75, 0.002);
  EXPECT_NEAR(map.areaM2(patch), 1.8, 0.2);  // 1.8 m x 1 m, to within the cell size
}

TEST(PatchMap, ParallelPlanesTenCentimetresApartStaySeparate) {
  PatchMap map(PatchMapConfig{});
  const std::vector<int> ids =
      map.add({strip(0.0, 1.0, 0.0, 1.0, 0.70), strip(0.0, 1.0, 0.0, 1.0, 0.80)});
  EXPECT_EQ(map.patches().size(), 2u);
  EXPECT_NE(ids[0], ids[1]);
}

TEST(PatchMap, APlaneTiltedBeyondTheAngleBoundIsANewPatch) {
  PatchMap map(PatchMapConfig{});
  map.add({strip(0.0, 1.0, 0.0, 1.0, 0.75)});
  map.add({strip(0.9, 1.9, 0.0, 1.0, 0.75 - 0.9 * 0.2, 0.0, 0.2)});  // 11 degrees, touching
  EXPECT_EQ(map.patches().size(), 2u);
}

TEST(PatchMap, TwoDisjointPartsThatLaterJoinBecomeOnePatch) {
  // A table seen first at its two ends (say, behind a vase), then whole.
  PatchMap map(PatchMapConfig{});
  const auto left = map.add({strip(0.0, 0.6, 0.0, 0.8, 0.75)});
  const auto right = map.add({strip(1.4, 2.0, 0.0, 0.8, 0.75)});
  ASSERT_EQ(map.patches().size(), 2u);
  ASSERT_NE(left[0], right[0]);
  const auto whole = map.add({strip(0.5, 1.5, 0.0, 0.8, 0.75)});
  ASSERT_EQ(map.patches().size(), 1u);
  EXPECT_EQ(whole[0], std::min(left[0], right[0]));  // the older patch is kept
  EXPECT_NEAR(map.areaM2(map.patches().front()), 2.0 * 0.8, 0.2);
  EXPECT_NEAR(std::abs(map.patches().front().offset()), 0.75, 1e-6);
}

TEST(PatchMap, RegionsOfARenderedPlaneBecomeWorldPoints) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.1, -0.2, -1.0).normalized();
  core::Isometry T_W_C = core::Isometry::Identity();
  T_W_C.translation() = Eigen::Vector3d(0.3, -0.1, 0.2);
  const double d = n.dot(Eigen::Vector3d(0.0, 0.0, 2.0));
  const core::Frame frame = test::renderPlane(test::kinectIntrinsics(), T_W_C, n, d);
  const PlaneDetection detection = PlaneDetector(PlaneDetectorConfig{}).detect(frame);
  const auto observations = observationsOf(frame, detection, T_W_C);
  ASSERT_EQ(observations.size(), 1u);
  ASSERT_GT(observations[0].points_W.size(), 50000u);
  double worst = 0.0;
  for (const auto& X : observations[0].points_W) worst = std::max(worst, std::abs(n.dot(X) - d));
  EXPECT_LT(worst, 0.003);  // millimetre depth rounding at about 2 m
}

// A wall 2 m away with a 40 cm square box face 1.2 m in front of it, seen from T_W_C: the
// nearest of the two along each ray, in millimetres.
core::Frame wallBehindBox(const core::Isometry& T_W_C) {
  core::Frame frame =
      test::renderPlane(test::kinectIntrinsics(), T_W_C, Eigen::Vector3d(0, 0, -1), -2.0);
  const core::Intrinsics& k = frame.intrinsics;
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const Eigen::Vector3d ray =
          T_W_C.linear() * Eigen::Vector3d((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
      const double t = (0.8 - T_W_C.translation().z()) / ray.z();
      const Eigen::Vector3d X = T_W_C.translation() + t * ray;
      if (t > 0.0 && std::abs(X.x()) <= 0.2 && std::abs(X.y()) <= 0.2) {
        frame.depth_mm.at<std::uint16_t>(v, u) = static_cast<std::uint16_t>(std::lround(t * 1000));
      }
    }
  }
  return frame;
}

TEST(PatchMap, AWallPartlyHiddenByClutterIsOnePatchWithAHoleThatFillsInFromOtherViews) {
  const PlaneDetector detector(PlaneDetectorConfig{});
  PatchMap map(PatchMapConfig{});
  auto see = [&](const core::Isometry& T_W_C) {
    const core::Frame frame = wallBehindBox(T_W_C);
    return map.add(observationsOf(frame, detector.detect(frame), T_W_C));
  };
  core::Isometry T_W_C = core::Isometry::Identity();
  see(T_W_C);
  ASSERT_EQ(map.patches().size(), 2u);  // the wall and the box's face
  const Patch* wall = nullptr;
  for (const Patch& p : map.patches()) {
    if (std::abs(std::abs(p.offset()) - 2.0) < 0.01) wall = &p;
  }
  ASSERT_NE(wall, nullptr);
  EXPECT_NEAR(std::abs(wall->normal().z()), 1.0, 1e-4);
  Outline outline = map.outlineOf(*wall);
  ASSERT_EQ(outline.parts.size(), 1u);
  ASSERT_EQ(outline.parts.front().holes.size(), 1u);
  // The box hides a 1 m square of wall (0.4 m at 0.8 m, seen from 2 m): 1 m^2, to within the
  // cells and the strips cut at the box's edge.
  const double hidden = polygonArea(outline.parts.front().holes.front());
  EXPECT_NEAR(hidden, 1.0, 0.25);
  const int wall_id = wall->id;

  // Seen again from 60 cm to the side, the box hides another part of the wall.
  T_W_C.translation() = Eigen::Vector3d(0.6, 0.0, 0.0);
  see(T_W_C);
  wall = map.find(wall_id);
  ASSERT_NE(wall, nullptr);
  outline = map.outlineOf(*wall);
  ASSERT_EQ(outline.parts.size(), 1u);
  double still_hidden = 0.0;
  for (const Polygon2& hole : outline.parts.front().holes) still_hidden += polygonArea(hole);
  EXPECT_LT(still_hidden, 0.5 * hidden);
  std::size_t walls = 0;
  for (const Patch& p : map.patches()) walls += std::abs(std::abs(p.offset()) - 2.0) < 0.03 ? 1 : 0;
  EXPECT_EQ(walls, 1u);
}

// Tiles: a plane that outgrows tile_m is cut on a grid of its plane into patches of at most
// tile_m a side, which share the plane; surfaces up to tile_m stay one patch.
struct CellBounds {
  int min_u = std::numeric_limits<int>::max(), max_u = std::numeric_limits<int>::min();
  int min_v = std::numeric_limits<int>::max(), max_v = std::numeric_limits<int>::min();
};

CellBounds boundsOf(const Patch& patch) {
  CellBounds b;
  for (const Cell& c : patch.cells) {
    b.min_u = std::min(b.min_u, c.first);
    b.max_u = std::max(b.max_u, c.first);
    b.min_v = std::min(b.min_v, c.second);
    b.max_v = std::max(b.max_v, c.second);
  }
  return b;
}

TEST(PatchTiles, AFloorLongerThanATileIsCutIntoTilesOfOnePlane) {
  PatchMapConfig config;
  config.tile_m = 6.0;
  PatchMap map(config);
  // A 14 m x 1 m corridor floor, seen 1.2 m at a time as the robot drives along it.
  for (double x = 0.0; x < 14.0; x += 1.0) {
    map.add({strip(x, std::min(x + 1.2, 14.0), 0.0, 1.0, 0.0, 0.003, 0.0, 7)});
  }
  ASSERT_EQ(map.patches().size(), 3u);  // 14 m in 6 m tiles
  const int cells_per_tile = static_cast<int>(std::lround(6.0 / config.cell_m));
  std::set<Cell> all_cells;
  double area = 0.0;
  for (const Patch& tile : map.patches()) {
    EXPECT_EQ(tile.plane, map.patches().front().plane);
    EXPECT_EQ(tile.geometry, map.patches().front().geometry);  // one plane, one cell grid
    const CellBounds b = boundsOf(tile);
    EXPECT_LE(b.max_u - b.min_u + 1, cells_per_tile);
    EXPECT_LE(b.max_v - b.min_v + 1, cells_per_tile);
    for (const Cell& c : tile.cells) EXPECT_TRUE(all_cells.insert(c).second);  // disjoint
    area += map.areaM2(tile);
  }
  EXPECT_NEAR(area, 14.0, 0.8);
  EXPECT_NEAR(std::abs(map.patches().front().offset()), 0.0, 0.002);
}

TEST(PatchTiles, ASurfaceNoLongerThanATileIsNeverCut) {
  PatchMapConfig config;
  config.tile_m = 6.0;
  PatchMap map(config);
  // Seen first near one end, then growing to 5.9 m: tile 0 is placed to hold it whole.
  for (double x = 5.0; x >= 0.0; x -= 1.0)
    map.add({strip(x, std::min(x + 1.1, 5.9), 0.0, 2.0, 0.75)});
  ASSERT_EQ(map.patches().size(), 1u);
  EXPECT_NEAR(map.areaM2(map.patches().front()), 5.9 * 2.0, 0.5);
}

TEST(PatchTiles, APlaneJoinedFromTwoPartsIsCutWhenTheJoinOutgrowsATile) {
  PatchMapConfig config;
  config.tile_m = 2.0;
  PatchMap map(config);
  map.add({strip(0.0, 1.5, 0.0, 0.8, 0.75)});
  map.add({strip(2.5, 4.0, 0.0, 0.8, 0.75)});
  ASSERT_EQ(map.patches().size(), 2u);
  ASSERT_NE(map.patches()[0].plane, map.patches()[1].plane);
  const auto joined = map.add({strip(1.4, 2.6, 0.0, 0.8, 0.75)});
  ASSERT_GE(map.patches().size(), 2u);
  double area = 0.0;
  bool region_tile_exists = false;
  for (const Patch& tile : map.patches()) {
    EXPECT_EQ(tile.plane, 0);  // the older plane took the other in
    const CellBounds b = boundsOf(tile);
    EXPECT_LE(b.max_u - b.min_u + 1, 40);
    area += map.areaM2(tile);
    region_tile_exists |= tile.id == joined[0];
  }
  EXPECT_TRUE(region_tile_exists);
  EXPECT_NEAR(area, 4.0 * 0.8, 0.3);
}

// Finalization on a synthetic sequence: a table top grows by 10 cm per frame for 20 frames,
// then stays the same while in view. With 10 stable frames it is finalized exactly when its
// area has not grown for 10 frames in view.
PatchMapConfig lifecycleConfig() {
  PatchMapConfig config;
  config.stable_frames = 10;
  config.max_growth = 0.02;
  config.out_of_view_frames = 15;
  config.min_area_m2 = 0.1;
  return config;
}

std::vector<PatchEvent> finalizations(const std::vector<PatchEvent>& events) {
  std::vector<PatchEvent> out;
  for (const auto& e : events) {
    if (e.kind == PatchEvent::Kind::kFinalized) out.push_back(e);
  }
  return out;
}

TEST(PatchLifecycle, AGrowingPatchIsFinalizedOnceItStopsGrowing) {
  PatchMap map(lifecycleConfig());
  long finalized_at = -1;
  for (long frame = 0; frame < 60; ++frame) {
    const double length = 0.5 + 0.1 * static_cast<double>(std::min(frame, 19L));
    map.add({strip(0.0, length, 0.0, 0.8, 0.75)});
    const auto events = finalizations(map.endFrame(frame));
    if (!events.empty() && finalized_at < 0) finalized_at = frame;
    EXPECT_LE(events.size(), 1u);
    for (const PatchEvent& e : events) EXPECT_STREQ(e.reason, "stable");
  }
  // Last growth at frame 19; ten frames later its area has not grown over ten frames in view.
  EXPECT_EQ(finalized_at, 29);
  EXPECT_EQ(map.finalizedCount(), 1u);
  EXPECT_EQ(map.liveCount(), 0u);
  EXPECT_EQ(map.patches().front().version, 1);
}

TEST(PatchLifecycle, APatchOutOfViewIsFinalizedAfterTheConfiguredFrames) {
  PatchMap map(lifecycleConfig());
  map.add({strip(0.0, 1.0, 0.0, 1.0, 0.75)});
  EXPECT_TRUE(map.endFrame(0).empty());
  for (long frame = 1; frame < 15; ++frame) EXPECT_TRUE(map.endFrame(frame).empty());
  const auto events = finalizations(map.endFrame(15));
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events.front().version, 1);
  EXPECT_STREQ(events.front().reason, "out of view");
  // One seen on the last frame and not yet stable is finalized by the end of the stream.
  map.add({strip(3.0, 4.0, 0.0, 1.0, 0.75)});
  EXPECT_TRUE(finalizations(map.endFrame(16)).empty());
  const auto at_end = finalizations(map.finalizeAll());
  ASSERT_EQ(at_end.size(), 1u);
  EXPECT_STREQ(at_end.front().reason, "end of stream");
}

TEST(PatchLifecycle, APatchThatGrowsAfterFinalizationGetsANewVersionNotADuplicate) {
  PatchMap map(lifecycleConfig());
  long frame = 0;
  for (; frame < 12; ++frame) {
    map.add({strip(0.0, 1.0, 0.0, 1.0, 0.75)});
    map.endFrame(frame);
  }
  ASSERT_EQ(map.patches().front().version, 1);
  const int id = map.patches().front().id;
  // The robot comes back and sees the table's other half.
  std::vector<PatchEvent> later;
  for (long end = frame + 12; frame < end; ++frame) {
    map.add({strip(0.5, 2.0, 0.0, 1.0, 0.75)});
    for (const auto& e : finalizations(map.endFrame(frame))) later.push_back(e);
  }
  ASSERT_EQ(map.patches().size(), 1u);
  ASSERT_EQ(later.size(), 1u);
  EXPECT_EQ(later.front().id, id);
  EXPECT_EQ(later.front().version, 2);
  EXPECT_NEAR(map.areaM2(map.patches().front()), 2.0, 0.2);
}

TEST(PatchLifecycle, AFinalizedPatchMergedIntoAnotherIsRetired) {
  PatchMap map(lifecycleConfig());
  for (long frame = 0; frame < 12; ++frame) {
    map.add({strip(0.0, 0.6, 0.0, 0.8, 0.75), strip(1.4, 2.0, 0.0, 0.8, 0.75)});
    map.endFrame(frame);
  }
  ASSERT_EQ(map.finalizedCount(), 2u);
  map.add({strip(0.5, 1.5, 0.0, 0.8, 0.75)});
  const auto events = map.endFrame(12);
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events.front().kind, PatchEvent::Kind::kRetired);
  EXPECT_EQ(events.front().id, 1);
  EXPECT_EQ(map.patches().size(), 1u);
  EXPECT_EQ(map.liveCount(), 1u);  // the joined table grew: it will be finalized again
  const auto last = finalizations(map.finalizeAll());
  ASSERT_EQ(last.size(), 1u);
  EXPECT_EQ(last.front().id, 0);
  EXPECT_EQ(last.front().version, 2);
}

TEST(PatchLifecycle, TinyPatchesAreNeverFinalized) {
  PatchMap map(lifecycleConfig());
  map.add({strip(0.0, 0.2, 0.0, 0.2, 0.75)});  // 0.04 m^2
  for (long frame = 0; frame < 40; ++frame) EXPECT_TRUE(map.endFrame(frame).empty());
  EXPECT_TRUE(map.finalizeAll().empty());
}

// Colour samples of a rendered checkerboard plane carry the board's colour at their position,
// one blended sample per 3.5 mm cell.
TEST(PatchColours, SamplesFromAFrameMatchTheColourOnThePlane) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.1, -0.2, -1.0).normalized();
  const core::Isometry T_W_C = core::Isometry::Identity();
  const double d = n.dot(Eigen::Vector3d(0.0, 0.0, 1.5));
  const core::Frame frame = test::renderPlane(test::kinectIntrinsics(), T_W_C, n, d);
  const PlaneDetection detection = PlaneDetector(PlaneDetectorConfig{}).detect(frame);
  PatchMap map(PatchMapConfig{});
  const auto ids = map.add(observationsOf(frame, detection, T_W_C));
  map.addColours(frame, detection, T_W_C, ids);
  ASSERT_EQ(map.patches().size(), 1u);
  const Patch& patch = map.patches().front();
  const auto samples = patch.samples->all();
  ASSERT_GT(samples.size(), 100000u);
  // 3.5 mm cells over the patch's area, one sample each, bound the count and the memory.
  const double cell = PatchMapConfig{}.sample_cell_m;
  EXPECT_LE(static_cast<double>(samples.size()), 1.2 * map.areaM2(patch) / (cell * cell));
  std::size_t matching = 0;
  for (const ColourSample& s : samples) {
    const Eigen::Vector3d X =
        patch.geometry->origin + s.u * patch.geometry->u_axis + s.v * patch.geometry->v_axis;
    const long parity = static_cast<long>(std::floor(X.x() * 10)) +
                        static_cast<long>(std::floor(X.y() * 10)) +
                        static_cast<long>(std::floor(X.z() * 10));
    const std::uint8_t expected = parity % 2 != 0 ? 40 : 220;
    if (s.rgb[0] == expected) ++matching;
  }
  // Only samples within a few millimetres of a square's edge may disagree.
  EXPECT_GT(static_cast<double>(matching), 0.97 * static_cast<double>(samples.size()));
}

// One rendered plane, coloured once, in a map whose released samples go to a fresh folder.
struct ColouredPlane {
  core::Frame frame;
  PlaneDetection detection;
  std::vector<int> ids;
};

ColouredPlane addColouredPlane(PatchMap& map, const std::filesystem::path& spill) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.1, -0.2, -1.0).normalized();
  const core::Isometry T_W_C = core::Isometry::Identity();
  ColouredPlane plane;
  plane.frame =
      test::renderPlane(test::kinectIntrinsics(), T_W_C, n, n.dot(Eigen::Vector3d(0, 0, 1.5)));
  plane.detection = PlaneDetector(PlaneDetectorConfig{}).detect(plane.frame);
  map.setSampleSpillDir(spill);
  plane.ids = map.add(observationsOf(plane.frame, plane.detection, T_W_C));
  map.addColours(plane.frame, plane.detection, T_W_C, plane.ids);
  return plane;
}

// Bounded memory: a finalized patch out of view for release_samples_after_frames frames moves
// its samples to a file; seen again, it gets them back exactly, and the file is gone.
TEST(PatchLifecycle, AFinalizedPatchOutOfViewReleasesItsSamplesAndGetsThemBackWhenSeen) {
  PatchMapConfig config = lifecycleConfig();
  config.release_samples_after_frames = 20;
  PatchMap map(config);
  const auto spill = test::freshTempDir() / "samples";
  const ColouredPlane plane = addColouredPlane(map, spill);
  ASSERT_EQ(map.patches().size(), 1u);
  const std::vector<ColourSample> before = map.patches().front().samples->all();
  ASSERT_GT(before.size(), 100000u);
  long f = 0;
  for (; f < 15; ++f) EXPECT_EQ(map.releaseIdleSamples(f), 0u);  // not finalized yet
  map.endFrame(0);
  for (f = 1; f <= 15; ++f) map.endFrame(f);  // finalized out of view at frame 15
  ASSERT_TRUE(map.patches().front().finalized);
  EXPECT_EQ(map.releaseIdleSamples(19), 0u);  // unseen for 19 frames only
  EXPECT_EQ(map.releaseIdleSamples(20), 1u);
  const Patch& released = map.patches().front();
  EXPECT_EQ(released.samples->size(), 0u);
  EXPECT_EQ(released.samples->bytes(), 0u);
  ASSERT_TRUE(released.spilled_samples);
  EXPECT_TRUE(std::filesystem::is_regular_file(*released.spilled_samples));
  EXPECT_EQ(map.releaseIdleSamples(40), 0u);  // released once

  map.add(observationsOf(plane.frame, plane.detection, core::Isometry::Identity()));  // again
  const Patch& back = map.patches().front();
  EXPECT_FALSE(back.spilled_samples);
  const std::vector<ColourSample> after = back.samples->all();
  ASSERT_EQ(after.size(), before.size());
  const auto key = [](const ColourSample& s) { return std::tuple(s.u, s.v, s.rgb, s.score); };
  std::vector<std::tuple<float, float, std::array<std::uint8_t, 3>, float>> a, b;
  for (const ColourSample& s : before) a.push_back(key(s));
  for (const ColourSample& s : after) b.push_back(key(s));
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  EXPECT_EQ(a, b);
  EXPECT_TRUE(std::filesystem::is_empty(spill));
}

// A spill folder that cannot take the file keeps the samples in memory.
TEST(PatchLifecycle, SamplesStayInMemoryWhenTheirFileCannotBeWritten) {
  PatchMapConfig config = lifecycleConfig();
  config.release_samples_after_frames = 5;
  PatchMap map(config);
  const auto spill = test::freshTempDir() / "samples";
  const ColouredPlane plane = addColouredPlane(map, spill);
  // A folder where the file should go: the file cannot be created.
  std::filesystem::create_directories(spill /
                                      ("patch_" + std::to_string(plane.ids.front()) + ".samples"));
  for (long f = 0; f <= 15; ++f) map.endFrame(f);
  ASSERT_TRUE(map.patches().front().finalized);
  EXPECT_EQ(map.releaseIdleSamples(30), 0u);
  EXPECT_GT(map.patches().front().samples->size(), 100000u);
  EXPECT_FALSE(map.patches().front().spilled_samples);
}

// A robot that drives on along a cut floor re-finalizes the tiles that grow, never the ones
// behind it: each version's samples and bitmap stay within one tile.
TEST(PatchTiles, DrivingOnReFinalizesOnlyTheTilesThatGrow) {
  PatchMapConfig config = lifecycleConfig();
  config.tile_m = 2.0;
  PatchMap map(config);
  long frame = 0;
  for (; frame < 12; ++frame) {  // the first 5.9 m, in view long enough to be finalized
    map.add({strip(0.0, 5.9, 0.0, 1.0, 0.0)});
    map.endFrame(frame);
  }
  std::map<int, int> first_versions;
  for (const Patch& tile : map.patches()) {
    EXPECT_EQ(tile.version, 1);
    first_versions[tile.id] = tile.version;
  }
  ASSERT_GE(first_versions.size(), 3u);
  std::vector<PatchEvent> later;
  for (long end = frame + 12; frame < end; ++frame) {  // on to 8 m, the start out of view
    map.add({strip(5.5, 8.0, 0.0, 1.0, 0.0)});
    for (const auto& e : finalizations(map.endFrame(frame))) later.push_back(e);
  }
  ASSERT_FALSE(later.empty());
  for (const PatchEvent& e : later) {
    const Patch* tile = map.find(e.id);
    ASSERT_NE(tile, nullptr);
    // Only tiles reaching past 5.5 m: the start of the floor keeps its first version.
    const CellBounds b = boundsOf(*tile);
    const Eigen::Vector3d far_end = tile->cellCentre({b.max_u, b.max_v}, config.cell_m);
    const Eigen::Vector3d near_end = tile->cellCentre({b.min_u, b.min_v}, config.cell_m);
    EXPECT_GT(std::max(far_end.x(), near_end.x()), 5.4) << "tile " << e.id;
    EXPECT_LE(e.area_m2, 2.0 * 2.0 + 1e-9);
  }
  for (const auto& [id, version] : first_versions) {
    const Patch* tile = map.find(id);
    const CellBounds b = boundsOf(*tile);
    const double reach = std::max(tile->cellCentre({b.max_u, b.max_v}, config.cell_m).x(),
                                  tile->cellCentre({b.min_u, b.min_v}, config.cell_m).x());
    if (reach < 5.4) {
      EXPECT_EQ(tile->version, 1) << "tile " << id;
    }
  }
}

// A frame's colours go to the tile where each pixel meets the plane, and tiles lose nothing
// against the plane not cut.
TEST(PatchTiles, ColoursGoToTheTileWhereThePixelMeetsThePlane) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.1, -0.2, -1.0).normalized();
  const core::Isometry T_W_C = core::Isometry::Identity();
  const core::Frame frame =
      test::renderPlane(test::kinectIntrinsics(), T_W_C, n, n.dot(Eigen::Vector3d(0, 0, 1.5)));
  const PlaneDetection detection = PlaneDetector(PlaneDetectorConfig{}).detect(frame);
  PatchMapConfig whole_config;
  whole_config.tile_m = 0.0;
  PatchMap whole(whole_config);
  whole.addColours(frame, detection, T_W_C, whole.add(observationsOf(frame, detection, T_W_C)));
  ASSERT_EQ(whole.patches().size(), 1u);

  PatchMapConfig cut_config;
  cut_config.tile_m = 0.5;
  PatchMap cut(cut_config);
  const auto ids = cut.add(observationsOf(frame, detection, T_W_C));
  cut.addColours(frame, detection, T_W_C, ids);
  ASSERT_GE(cut.patches().size(), 6u);  // about 1.6 x 1.3 m in 0.5 m tiles
  std::size_t samples = 0;
  const int cells_per_tile = static_cast<int>(std::lround(0.5 / cut_config.cell_m));
  for (const Patch& tile : cut.patches()) {
    const CellBounds b = boundsOf(tile);
    for (const ColourSample& s : tile.samples->all()) {
      // Within the tile's window of cells (its cells' bounds, grown to a whole tile).
      const int cu = static_cast<int>(std::floor(s.u / cut_config.cell_m));
      const int cv = static_cast<int>(std::floor(s.v / cut_config.cell_m));
      EXPECT_GT(cu, b.max_u - cells_per_tile);
      EXPECT_LT(cu, b.min_u + cells_per_tile);
      EXPECT_GT(cv, b.max_v - cells_per_tile);
      EXPECT_LT(cv, b.min_v + cells_per_tile);
    }
    samples += tile.samples->size();
  }
  const double expected = static_cast<double>(whole.patches().front().samples->size());
  EXPECT_NEAR(static_cast<double>(samples), expected, 0.01 * expected);
}

// The test-sized version of the long-run bench: a camera drives 20 m along a floor, 10 cm a
// frame. With tiles the colour samples in memory stay bounded (finalized tiles behind the
// camera release theirs); one uncut plane holds the whole floor's.
struct DriveMemory {
  std::size_t peak_first_half = 0, peak_second_half = 0, at_end = 0;
  std::size_t patches = 0, released = 0;
  double largest_finalized_m2 = 0.0;
};

DriveMemory driveAlongAFloor(PatchMapConfig config, const std::filesystem::path& spill) {
  constexpr int kFrames = 200;
  PatchMap map(config);
  map.setSampleSpillDir(spill);
  const PlaneDetector detector{PlaneDetectorConfig{}};
  const double c = std::cos(M_PI / 4.0), s = std::sin(M_PI / 4.0);
  DriveMemory memory;
  for (long frame = 0; frame < kFrames; ++frame) {
    // 1 m above the floor, looking along +x and 45 degrees down.
    core::Isometry T_W_C = core::Isometry::Identity();
    T_W_C.linear().col(0) = Eigen::Vector3d(0.0, -1.0, 0.0);
    T_W_C.linear().col(1) = Eigen::Vector3d(-s, 0.0, -c);
    T_W_C.linear().col(2) = Eigen::Vector3d(c, 0.0, -s);
    T_W_C.translation() = Eigen::Vector3d(0.1 * static_cast<double>(frame), 0.0, 1.0);
    const core::Frame image =
        test::renderPlane(test::kinectIntrinsics(), T_W_C, Eigen::Vector3d::UnitZ(), 0.0);
    const PlaneDetection detection = detector.detect(image);
    const auto ids = map.add(observationsOf(image, detection, T_W_C));
    if (frame % 2 == 0) map.addColours(image, detection, T_W_C, ids);
    for (const PatchEvent& e : map.endFrame(frame)) {
      if (e.kind == PatchEvent::Kind::kFinalized) {
        memory.largest_finalized_m2 = std::max(memory.largest_finalized_m2, e.area_m2);
      }
    }
    map.releaseIdleSamples(frame);
    std::size_t bytes = 0;
    for (const Patch& patch : map.patches()) bytes += patch.samples->bytes();
    std::size_t& peak = frame < kFrames / 2 ? memory.peak_first_half : memory.peak_second_half;
    peak = std::max(peak, bytes);
    memory.at_end = bytes;
  }
  memory.patches = map.patches().size();
  memory.released = map.samplesReleased();
  return memory;
}

TEST(PatchTiles, ALongDriveKeepsTheColourSamplesInMemoryBounded) {
  PatchMapConfig config = lifecycleConfig();
  config.release_samples_after_frames = 20;
  config.tile_m = 2.0;
  const DriveMemory tiled = driveAlongAFloor(config, test::freshTempDir() / "tiled");
  config.tile_m = 0.0;
  const DriveMemory uncut = driveAlongAFloor(config, test::freshTempDir() / "uncut");

  EXPECT_GE(tiled.patches, 10u);  // about 22 m of floor seen, in 2 m tiles
  EXPECT_GE(tiled.released, 4u);
  EXPECT_LE(tiled.largest_finalized_m2, 2.0 * 2.0 + 1e-9);
  // No growth: the second half of the drive holds no more than the first half did.
  EXPECT_LE(static_cast<double>(tiled.peak_second_half),
            1.2 * static_cast<double>(tiled.peak_first_half))
      << tiled.peak_first_half << " bytes, then " << tiled.peak_second_half;
  // The uncut floor is one patch in view all along, never stable: it keeps every sample.
  EXPECT_EQ(uncut.patches, 1u);
  EXPECT_EQ(uncut.released, 0u);
  EXPECT_GT(static_cast<double>(uncut.at_end), 2.5 * static_cast<double>(tiled.peak_second_half))
      << uncut.at_end << " bytes uncut, " << tiled.peak_second_half << " tiled";
}

}  // namespace
}  // namespace tessera::planes
