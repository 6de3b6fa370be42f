// The patch map after a loop closure: planes move with the keyframes they were seen from, and a
// wall mapped twice (before and after the drift) becomes one patch with a new version.
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "support/synthetic_plane.h"
#include "tessera/planes/patch_map.h"

namespace tessera::planes {
namespace {

PatchMapConfig quickConfig() {
  PatchMapConfig config;
  config.stable_frames = 5;
  config.out_of_view_frames = 5;
  config.moved_settle_frames = 8;
  return config;
}

// The wall z = wall_z (1.5) seen by a camera truly at `T_true`, placed in the map from the tracked
// pose `T_tracked` (drifted) moved by `loop_motion`, tracked after the keyframe at `keyframe_ns`,
// colours included.
std::vector<int> seeWall(PatchMap& map, const core::Isometry& T_true,
                         const core::Isometry& T_tracked, std::int64_t keyframe_ns,
                         const core::Isometry& loop_motion = core::Isometry::Identity(),
                         double wall_z = 1.5) {
  const core::Frame frame =
      test::renderPlane(test::kinectIntrinsics(), T_true, Eigen::Vector3d::UnitZ(), wall_z);
  const PlaneDetection detection = PlaneDetector(PlaneDetectorConfig{}).detect(frame);
  const core::Isometry T_map = loop_motion * T_tracked;
  std::vector<PlaneObservation> observations = observationsOf(frame, detection, T_map);
  for (PlaneObservation& observation : observations) {
    observation.keyframe_ns = keyframe_ns;
    observation.loop_motion = loop_motion;
  }
  const std::vector<int> ids = map.add(observations);
  map.addColours(frame, detection, T_map, ids);
  return ids;
}

core::Isometry shifted(double x, double z) {
  core::Isometry T = core::Isometry::Identity();
  T.translation() = Eigen::Vector3d(x, 0.0, z);
  return T;
}

std::size_t countOf(const std::vector<PatchEvent>& events, PatchEvent::Kind kind) {
  std::size_t n = 0;
  for (const PatchEvent& e : events) n += e.kind == kind ? 1 : 0;
  return n;
}

// Before the loop: the wall from the start (time 1000..), then seen again 0.4 m along it after
// 10 cm of drift along its normal (time 5000..), which makes a second patch. The loop closure's
// correction (-10 cm for keyframes from time 5000) moves the second onto the first, and it
// merges: one patch, a new version from both views' samples, the doubled one retired.
TEST(PatchCorrection, ADoubledWallMergesIntoOnePatchAfterTheLoopCloses) {
  PatchMap map(quickConfig());
  long frame = 0;
  std::vector<PatchEvent> events;
  const auto endFrame = [&] {
    for (const PatchEvent& e : map.endFrame(frame++)) events.push_back(e);
  };
  for (int i = 0; i < 8; ++i) {
    seeWall(map, shifted(0.0, 0.0), shifted(0.0, 0.0), 1000 + i);
    endFrame();
  }
  const core::Isometry T_true = shifted(0.4, 0.0), T_drifted = shifted(0.4, 0.1);
  for (int i = 0; i < 8; ++i) {
    seeWall(map, T_true, T_drifted, 5000 + i);
    endFrame();
  }
  ASSERT_EQ(map.patches().size(), 2u) << "the drifted view should double the wall";
  ASSERT_EQ(countOf(events, PatchEvent::Kind::kFinalized), 2u);
  const int first = map.patches()[0].id, doubled = map.patches()[1].id;
  const std::size_t first_samples = map.patches()[0].samples->size();
  const double first_area = map.areaM2(map.patches()[0]);

  // The pose graph's answer: keyframes from time 5000 on were 10 cm too far along +z.
  const auto motion_at = [](std::int64_t t) {
    return t >= 5000 ? shifted(0.0, -0.1) : core::Isometry::Identity();
  };
  EXPECT_EQ(map.followCorrection(motion_at), 1u);  // only the doubled wall moves
  ASSERT_EQ(map.patches().size(), 2u);
  const Patch& moved = map.patches()[1];
  EXPECT_NEAR(std::abs(moved.offset()), 1.5, 0.003);
  EXPECT_NEAR(std::abs(moved.normal().z()), 1.0, 1e-6);
  // The same correction again moves nothing.
  EXPECT_EQ(map.followCorrection(motion_at), 0u);

  EXPECT_EQ(map.mergeCoinciding(), 1u);
  ASSERT_EQ(map.patches().size(), 1u);
  const Patch& wall = map.patches().front();
  EXPECT_EQ(wall.id, first);
  EXPECT_NEAR(std::abs(wall.offset()), 1.5, 0.003);
  EXPECT_GT(map.areaM2(wall), first_area + 0.3);  // 0.4 m more along x, over > 1 m of height
  EXPECT_GT(wall.samples->size(), first_samples);
  EXPECT_FALSE(wall.finalized);

  events.clear();
  endFrame();
  EXPECT_EQ(countOf(events, PatchEvent::Kind::kRetired), 1u);
  EXPECT_EQ(events.front().id, doubled);
  for (const PatchEvent& e : map.finalizeAll()) events.push_back(e);
  ASSERT_EQ(countOf(events, PatchEvent::Kind::kFinalized), 1u);
  EXPECT_EQ(events.back().id, first);
  EXPECT_EQ(events.back().version, 2);

  // Later frames of the corrected keyframes go to the merged wall.
  const std::vector<int> ids = seeWall(map, T_true, T_drifted, 6000, motion_at(6000));
  ASSERT_FALSE(ids.empty());
  EXPECT_EQ(ids.front(), first);
  EXPECT_EQ(map.patches().size(), 1u);
}

// Two real walls 10 cm apart (a wall and a board hung on it) are not a place mapped twice: a
// correction that leaves them where they are merges nothing.
TEST(PatchCorrection, ParallelWallsACorrectionLeavesApartStaySeparate) {
  PatchMap map(quickConfig());
  seeWall(map, shifted(0.0, 0.0), shifted(0.0, 0.0), 1000);
  map.endFrame(0);
  seeWall(map, shifted(0.0, -0.1), shifted(0.0, 0.0), 5000);  // seen 10 cm nearer
  map.endFrame(1);
  ASSERT_EQ(map.patches().size(), 2u);
  EXPECT_EQ(map.followCorrection([](std::int64_t t) {
    return t >= 5000 ? shifted(0.02, 0.0) : core::Isometry::Identity();  // along the wall
  }),
            1u);
  EXPECT_EQ(map.mergeCoinciding(), 0u);
  EXPECT_EQ(map.patches().size(), 2u);
}

// One fit cannot follow a long plane that tracking drift bent: a piece 4 cm off it, at its far
// end, merges after a correction; the same 4 cm near the plane's centroid is a step and stays.
TEST(PatchCorrection, APieceOfABentPlaneMergesAtItsFarEndButNotNearItsCentroid) {
  const auto seeLongWall = [](PatchMap& map) {
    for (int i = 0; i <= 8; ++i) seeWall(map, shifted(i, 0.0), shifted(i, 0.0), 1000 * i);
    map.endFrame(0);
    return map.patches().size();
  };
  for (const double piece_x : {9.0, 4.0}) {
    PatchMap map(quickConfig());
    const std::size_t wall_patches = seeLongWall(map);
    seeWall(map, shifted(piece_x, 0.0), shifted(piece_x, -0.04), 9000);  // 4 cm nearer
    map.endFrame(1);
    ASSERT_GT(map.patches().size(), wall_patches) << "the piece 4 cm off makes a plane of its own";
    const bool far_end = piece_x > 8.0;
    EXPECT_EQ(map.mergeCoinciding(), far_end ? 1u : 0u) << "piece at x = " << piece_x;
  }
}

// The share of points, 1 cm inside the edges of the checkerboard's 10 cm squares across the
// wall z = 1.5 from x = x_lo to x_hi, whose colour in the map is not the wall's there.
double wrongColourShare(const PatchMap& map, double x_lo, double x_hi, double wall_z = 1.5) {
  std::size_t wrong = 0, compared = 0;
  for (double x = x_lo; x < x_hi; x += 0.1) {
    for (const double dx : {0.01, 0.09}) {
      for (double y = -0.45; y < 0.5; y += 0.1) {
        const Eigen::Vector3d X(x + dx, y, wall_z);
        const bool dark =
            (static_cast<long>(std::floor(X.x() * 10)) + static_cast<long>(std::floor(X.y() * 10)) +
             static_cast<long>(std::floor(X.z() * 10))) %
                2 !=
            0;
        for (const Patch& patch : map.patches()) {
          const PlaneGeometry& g = *patch.geometry;
          if (std::abs((X - g.origin).dot(g.normal)) > 0.05) continue;  // another plane
          const auto colour =
              patch.samples->colourAt(static_cast<float>((X - g.origin).dot(g.u_axis)),
                                      static_cast<float>((X - g.origin).dot(g.v_axis)));
          if (!colour) continue;
          ++compared;
          wrong += ((*colour)[0] < 130.0F) != dark ? 1 : 0;
          break;
        }
      }
    }
  }
  return compared == 0 ? 1.0 : static_cast<double>(wrong) / static_cast<double>(compared);
}

// A wall fused from two keyframes side by side: three frames at x = 0 (keyframe stamps 1000 on),
// then three at x = 1.8 m placed `drift_m` too far along the wall (stamps 5000 on), stamps
// `stamp_offset` later, from frame `frame` on. Returns the next frame number.
long seeWallFromTwoKeyframes(PatchMap& map, double drift_m, long frame = 0, double wall_z = 1.5,
                             std::int64_t stamp_offset = 0) {
  const core::Isometry same = core::Isometry::Identity();
  for (int i = 0; i < 3; ++i) {
    seeWall(map, shifted(0.0, 0.0), shifted(0.0, 0.0), 1000 + stamp_offset + i, same, wall_z);
    map.endFrame(frame++);
  }
  for (int i = 0; i < 3; ++i) {
    seeWall(map, shifted(1.8, 0.0), shifted(1.8 + drift_m, 0.0), 5000 + stamp_offset + i, same,
            wall_z);
    map.endFrame(frame++);
  }
  return frame;
}

// A wall fused from two keyframes side by side, the second placed 3 cm too far along the wall
// (drift along it, which moving the plane cannot show). The correction moves the second
// keyframe 3 cm back: the plane as a whole moves by the mean, about 1.5 cm, and each half's
// cells and colours move within the plane by the rest, so that both halves' checkerboards are
// where the wall has them.
TEST(PatchCorrection, CellsMoveWithinThePlaneByTheirOwnKeyframesCorrection) {
  PatchMap map(quickConfig());
  seeWallFromTwoKeyframes(map, 0.03);
  ASSERT_EQ(map.patches().size(), 1u) << "the two views should make one wall";
  ASSERT_EQ(map.planes().size(), 1u);
  EXPECT_GT(map.planes().begin()->second.blocks.size(), 100u);
  // Before the correction the second half's squares sit 3 cm off: about half the points 1 cm
  // inside an edge show the neighbouring square's colour.
  EXPECT_LT(wrongColourShare(map, -0.8, 0.8), 0.02);
  EXPECT_GT(wrongColourShare(map, 1.0, 2.6), 0.4);

  EXPECT_EQ(map.followCorrection([](std::int64_t t) {
    return t >= 5000 ? shifted(-0.03, 0.0) : core::Isometry::Identity();
  }),
            1u);
  ASSERT_EQ(map.patches().size(), 1u);
  EXPECT_LT(wrongColourShare(map, -0.8, 0.8), 0.02);
  EXPECT_LT(wrongColourShare(map, 1.0, 2.6), 0.02);
  // The wall's cells cover its two views again: none pushed apart or piled up.
  const double area = map.areaM2(map.patches().front());
  EXPECT_FALSE(map.patches().front().finalized);
  // The same correction again moves nothing within the plane.
  EXPECT_EQ(map.followCorrection([](std::int64_t t) {
    return t >= 5000 ? shifted(-0.03, 0.0) : core::Isometry::Identity();
  }),
            0u);
  EXPECT_NEAR(map.areaM2(map.patches().front()), area, 1e-9);
}

// A correction too small to show (under patches.min_move_within_plane_m) moves no tile within
// its plane, but is owed: the next one adds to it, and the tile then moves by both. Its new
// version waits moved_settle_frames frames after the move, so that a burst of corrections
// textures it once.
TEST(PatchCorrection, SmallMovesWithinThePlaneAddUpAndTheNewVersionWaitsForTheBurstToEnd) {
  PatchMap map(quickConfig());
  long frame = seeWallFromTwoKeyframes(map, 0.03);
  std::vector<PatchEvent> events = map.finalizeAll();
  ASSERT_EQ(finalizedIds(events).size(), 1u);
  const auto back_by = [](double x) {
    return
        [x](std::int64_t t) { return t >= 5000 ? shifted(-x, 0.0) : core::Isometry::Identity(); };
  };
  // 1.2 cm back: each half is owed about 6 mm, under the 1 cm a tile waits for.
  map.followCorrection(back_by(0.012));
  EXPECT_EQ(map.tilesMovedWithinPlanes(), 0u);
  EXPECT_TRUE(map.patches().front().finalized);
  EXPECT_GT(wrongColourShare(map, 1.0, 2.6), 0.2);
  // The rest of the 3 cm: the owed 6 mm and these 9 mm move the tile.
  map.followCorrection(back_by(0.03));
  EXPECT_EQ(map.tilesMovedWithinPlanes(), 1u);
  EXPECT_LT(wrongColourShare(map, -0.8, 0.8), 0.02);
  EXPECT_LT(wrongColourShare(map, 1.0, 2.6), 0.02);
  ASSERT_FALSE(map.patches().front().finalized);
  // Out of view, it is finalized again only once moved_settle_frames have passed.
  const long moved_at = frame;
  std::vector<long> finalized_at;
  for (int i = 0; i < 2 * quickConfig().moved_settle_frames; ++i) {
    for (const PatchEvent& e : map.endFrame(frame)) {
      if (e.kind == PatchEvent::Kind::kFinalized) finalized_at.push_back(frame);
    }
    ++frame;
  }
  ASSERT_EQ(finalized_at.size(), 1u);
  EXPECT_EQ(finalized_at.front() - moved_at, quickConfig().moved_settle_frames);
}

// Two walls a metre apart, each fused from two keyframes 3 cm apart (the far wall's two views
// overlap more, so its check is where only the second saw it), corrected at once with at
// most one tile moved a frame (patches.max_tiles_moved_per_frame): the first plane's tile moves
// with the correction, the second's at the next frame's call, or before a frame's points go
// to it, or, when the stream ends first, before the end finalizes it.
TEST(PatchCorrection, MovesWithinPlanesAreSpreadOverTheFramesAfterTheCorrection) {
  PatchMapConfig config = quickConfig();
  config.max_tiles_moved_per_frame = 1;
  constexpr double kFarWall_z = 2.5;
  const auto back = [](std::int64_t t) {
    return t >= 5000 ? shifted(-0.03, 0.0) : core::Isometry::Identity();
  };
  enum class Then { kNextCall, kPointsArrive, kStreamEnds };
  for (const Then then : {Then::kNextCall, Then::kPointsArrive, Then::kStreamEnds}) {
    SCOPED_TRACE(static_cast<int>(then));
    PatchMap map(config);
    const long frame = seeWallFromTwoKeyframes(map, 0.03);
    seeWallFromTwoKeyframes(map, 0.03, frame, kFarWall_z, 100);
    ASSERT_EQ(map.planes().size(), 2u);
    ASSERT_GT(wrongColourShare(map, 1.0, 2.6), 0.4);
    ASSERT_GT(wrongColourShare(map, 2.6, 3.4, kFarWall_z), 0.2);

    EXPECT_EQ(map.followCorrection(back), 2u);
    EXPECT_EQ(map.tilesMovedWithinPlanes(), 1u);
    EXPECT_TRUE(map.withinPlaneMovesPending());
    EXPECT_LT(wrongColourShare(map, 1.0, 2.6), 0.02);  // the near wall's plane came first
    EXPECT_GT(wrongColourShare(map, 2.6, 3.4, kFarWall_z), 0.2);

    if (then == Then::kStreamEnds) {
      EXPECT_EQ(finalizedIds(map.finalizeAll()).size(), 2u);
    } else if (then == Then::kPointsArrive) {
      seeWall(map, shifted(1.8, 0.0), shifted(1.83, 0.0), 5105, back(5105), kFarWall_z);
    } else {
      EXPECT_EQ(map.moveWithinPlanes(), 1u);
    }
    EXPECT_FALSE(map.withinPlaneMovesPending());
    EXPECT_EQ(map.tilesMovedWithinPlanes(), 2u);
    EXPECT_LT(wrongColourShare(map, 1.0, 2.6), 0.02);
    EXPECT_LT(wrongColourShare(map, 2.6, 3.4, kFarWall_z), 0.02);
    EXPECT_EQ(map.moveWithinPlanes(), 0u);
  }
}

// A region that continues two planes merges them, but not while the newer one still waits for
// moves within it (that would make all its moves in that frame): the doubled wall's planes
// merge once the moves are made. A far wall (the first plane) takes the frame's budget.
TEST(PatchCorrection, ARegionDoesNotMergePlanesWhileTheirMovesWait) {
  PatchMapConfig config = quickConfig();
  config.max_tiles_moved_per_frame = 1;
  PatchMap map(config);
  constexpr double kFarWall_z = 2.5;
  long frame = seeWallFromTwoKeyframes(map, 0.03, 0, kFarWall_z, 100);  // 1100.., 5100..
  // The near wall from keyframes 2000.., then the same wall seen again from keyframes 7000.. and
  // 8000.., placed 10 cm too far along its normal and the second also 3 cm along it: the place
  // mapped twice, the second time by a plane whose halves owe different moves.
  for (int i = 0; i < 3; ++i) {
    seeWall(map, shifted(0.0, 0.0), shifted(0.0, 0.0), 2000 + i);
    map.endFrame(frame++);
  }
  for (int i = 0; i < 3; ++i) {
    seeWall(map, shifted(0.4, 0.0), shifted(0.4, 0.1), 7000 + i);
    map.endFrame(frame++);
  }
  for (int i = 0; i < 3; ++i) {
    seeWall(map, shifted(1.8, 0.0), shifted(1.83, 0.1), 8000 + i);
    map.endFrame(frame++);
  }
  ASSERT_EQ(map.planes().size(), 3u);
  const auto motion_at = [](std::int64_t t) {
    if (t >= 8000) return shifted(-0.03, -0.1);
    if (t >= 7000) return shifted(0.0, -0.1);
    if (t >= 5000) return shifted(-0.03, 0.0);
    return core::Isometry::Identity();
  };
  map.followCorrection(motion_at);
  ASSERT_TRUE(map.withinPlaneMovesPending()) << "the doubled wall's moves should wait";
  const std::size_t moved = map.tilesMovedWithinPlanes();

  // A frame from the corrected keyframe sees the place mapped twice: both planes continue.
  seeWall(map, shifted(0.4, 0.0), shifted(0.4, 0.1), 7100, motion_at(7100));
  map.endFrame(frame++);
  EXPECT_EQ(map.planes().size(), 3u);
  EXPECT_EQ(map.tilesMovedWithinPlanes(), moved);
  EXPECT_TRUE(map.withinPlaneMovesPending());

  EXPECT_GT(map.moveWithinPlanes(), 0u);
  EXPECT_FALSE(map.withinPlaneMovesPending());
  EXPECT_EQ(map.mergeCoinciding(), 1u);
  EXPECT_EQ(map.planes().size(), 2u);
  EXPECT_LT(wrongColourShare(map, 2.0, 2.6), 0.02);
}

// The share of colour samples that lie outside their tile's cells (beyond one cell's margin).
double samplesOffTheirCells(const PatchMap& map, double cell_m) {
  std::size_t off = 0, all = 0;
  for (const Patch& patch : map.patches()) {
    for (const ColourSample& sample : patch.samples->all()) {
      const Cell cell{static_cast<int>(std::floor(sample.u / cell_m)),
                      static_cast<int>(std::floor(sample.v / cell_m))};
      bool near = false;
      for (int du = -1; du <= 1 && !near; ++du) {
        for (int dv = -1; dv <= 1 && !near; ++dv) {
          near = patch.cells.count({cell.first + du, cell.second + dv}) > 0;
        }
      }
      ++all;
      off += near ? 0 : 1;
    }
  }
  return all == 0 ? 1.0 : static_cast<double>(off) / static_cast<double>(all);
}

// A drift of 9.6 cm taken out by eight corrections of 1.2 cm each: colours move by the exact
// amount each time and cells by whole cells, so that after all of them the colours are where
// the wall has them and the cells still lie under them (their lag within half a cell).
TEST(PatchCorrection, ManySmallCorrectionsKeepTheCellsUnderTheirColours) {
  PatchMap map(quickConfig());
  seeWallFromTwoKeyframes(map, 0.096);
  ASSERT_EQ(map.patches().size(), 1u);
  const double cell_m = quickConfig().cell_m;
  EXPECT_LT(samplesOffTheirCells(map, cell_m), 0.001);
  for (int k = 1; k <= 8; ++k) {
    map.followCorrection([k](std::int64_t t) {
      return t >= 5000 ? shifted(-0.012 * k, 0.0) : core::Isometry::Identity();
    });
  }
  EXPECT_GT(map.tilesMovedWithinPlanes(), 2u);
  EXPECT_LT(wrongColourShare(map, -0.8, 0.8), 0.02);
  EXPECT_LT(wrongColourShare(map, 1.0, 2.6), 0.02);
  EXPECT_LT(samplesOffTheirCells(map, cell_m), 0.001);
}

}  // namespace
}  // namespace tessera::planes
