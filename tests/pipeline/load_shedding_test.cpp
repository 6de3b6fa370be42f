// Live load shedding (LoadShedding, stages.h): a late frame leaves out the work a frame can do
// without, at most LoadShedding::kMaxInARow frames in a row, and a replay never does.
#include <gtest/gtest.h>

#include "support/synthetic_plane.h"
#include "tessera/core/clock.h"
#include "tessera/pipeline/stages.h"

namespace tessera::pipeline {
namespace {

// Far above the default (50 ms), so that a frame that arrived just now is on time however
// slowly a sanitizer build processes it.
constexpr double kShedAfterMs = 10'000.0;

// A still camera's frame `index` of a plane 1.4 m away, arrived a minute ago when `late`,
// just now otherwise; `replay`: no arrival time, as a recording's frames.
core::Frame frameOf(std::uint64_t index, bool late, bool replay = false) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.1, 0.2, -1.0).normalized();
  core::Frame frame =
      test::renderPlane(test::kinectIntrinsics(), core::Isometry::Identity(), n, n.z() * 1.4);
  frame.index = index;
  frame.timestamp_ns = static_cast<std::int64_t>(index) * 33'333'333;
  frame.arrival_ns = replay ? 0 : core::steadyNowNs() - (late ? 60'000'000'000 : 0);
  return frame;
}

TrackedFrame trackedOf(core::Frame frame) {
  TrackedFrame tracked;
  tracked.frame = std::move(frame);
  tracked.T_W_C = core::Isometry::Identity();
  return tracked;
}

TEST(LoadShedding, ALateFrameLeavesItsIntegrationToTheNextAtMostTwiceInARow) {
  fusion::TsdfConfig tsdf;  // every 2nd frame
  IntegrationStage stage(tsdf, 1);
  stage.shedLoad({kShedAfterMs});
  const bool late[] = {true, false, true, true, true, false, false, true};
  std::vector<std::uint64_t> integrated;
  for (std::uint64_t i = 0; i < 8; ++i) {
    if (stage.process(trackedOf(frameOf(i, late[i]))).integrated) integrated.push_back(i);
  }
  // 0 is the first; 2 and 3 are due but late; 4 is late a third time and integrated; 6 is due
  // and on time; 7 is late but not due.
  EXPECT_EQ(integrated, (std::vector<std::uint64_t>{0, 4, 6}));
  EXPECT_EQ(stage.figures().frames_shed, 2u);
}

TEST(LoadShedding, AReplayIsNeverLate) {
  fusion::TsdfConfig tsdf;
  IntegrationStage stage(tsdf, 1);
  stage.shedLoad({kShedAfterMs});
  std::vector<std::uint64_t> integrated;
  for (std::uint64_t i = 0; i < 6; ++i) {
    if (stage.process(trackedOf(frameOf(i, false, true))).integrated) integrated.push_back(i);
  }
  EXPECT_EQ(integrated, (std::vector<std::uint64_t>{0, 2, 4}));
  EXPECT_EQ(stage.figures().frames_shed, 0u);
}

// Runs `frames` frames of the still plane through a plane stage; the frames are late or on
// time. Returns the stage and which frames found planes.
struct PlaneRun {
  PlaneFigures figures;
  std::vector<std::uint64_t> searched;
};
PlaneRun runPlaneStage(std::uint64_t frames, bool late) {
  PlaneStage planes({}, {}, {});
  planes.shedLoad({kShedAfterMs});
  PlaneRun run;
  for (std::uint64_t i = 0; i < frames; ++i) {
    TrackedFrame tracked = trackedOf(frameOf(i, late));
    FusedFrame fused;
    fused.frame = std::move(tracked.frame);
    fused.T_W_C = tracked.T_W_C;
    fused.integrated = true;
    const FusedFrame out = planes.process(std::move(fused));
    EXPECT_TRUE(out.T_W_C_planes.has_value()) << "frame " << i << " left unposed";
    if (out.figures.planes_detected > 0) run.searched.push_back(i);
  }
  run.figures = planes.figures();
  return run;
}

// Late frames leave their plane search to the next, at most twice in a row: the map sees every
// third frame, and each of them is posed all the same.
TEST(LoadShedding, ALateFrameLeavesItsPlaneSearchToTheNextAtMostTwiceInARow) {
  const PlaneRun late = runPlaneStage(9, true);
  EXPECT_EQ(late.searched, (std::vector<std::uint64_t>{2, 5, 8}));
  EXPECT_EQ(late.figures.plane_searches_shed, 6u);
  const PlaneRun on_time = runPlaneStage(9, false);
  EXPECT_EQ(on_time.searched.size(), 9u);
  EXPECT_EQ(on_time.figures.plane_searches_shed, 0u);
}

// The plane stage's colour sampling, due on even frames: late frames owe it to the next, and
// the third late frame in a row samples. Late, only frames 2, 5 and 8 are searched: 2 is due
// and sheds, 5 (owed) sheds, 8 samples.
TEST(LoadShedding, ALateFrameOwesItsColoursToTheNext) {
  EXPECT_EQ(runPlaneStage(9, true).figures.colour_frames_shed, 2u);
  EXPECT_EQ(runPlaneStage(9, false).figures.colour_frames_shed, 0u);
}

}  // namespace
}  // namespace tessera::pipeline
