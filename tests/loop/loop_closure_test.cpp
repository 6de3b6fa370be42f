// Loop closure: place recognition and the revisit check on rendered views, the pose graph's
// line process against a wrong loop, and the loop graph on two passes through one place and
// through two identical places.
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "support/keyframe_record.h"
#include "support/synthetic_office.h"
#include "support/test_data.h"
#include "tessera/core/registration.h"
#include "tessera/drivers/synthetic/scene.h"
#include "tessera/fusion/place_index.h"
#include "tessera/loop/loop_graph.h"
#include "tessera/loop/pose_graph.h"
#include "tessera/loop/revisit.h"

namespace tessera::loop {
namespace {

namespace synthetic = drivers::synthetic;

synthetic::Scene scene(const char* name) {
  return synthetic::loadScene(test::sourceDir() / "config/scenes" / name);
}

// The tracker's keyframe record of `frame`, posed at T_W_C.
fusion::KeyframeRecord keyframeOf(const core::Frame& frame, const core::Isometry& T_W_C) {
  return test::keyframeRecordOf(frame, T_W_C, static_cast<std::int64_t>(frame.index) * 33'333'333);
}

KeyframeView viewOf(const fusion::KeyframeRecord& record, int id, const LoopConfig& config) {
  KeyframeView view;
  view.id = id;
  view.T_W_C = record.T_W_C;
  view.features = record.features;
  view.intrinsics = record.intrinsics;
  view.depth_m = strideDepth(record.depth_m, config.dense_stride);
  return view;
}

// Rendered revisits and distinct places in the loop scene, a corridor ring: the keyframes are
// the walk's first 200 frames (the south corridor); the walk's second pass along it is a
// revisit, the north corridor (same floor, walls and kind of posters) is not.
TEST(PlaceRecognition, FindsARenderedRevisitAndNotADistinctPlace) {
  const synthetic::Scene loop_scene = scene("loop.yaml");
  const LoopConfig config;
  fusion::PlaceIndex index(4);
  std::vector<KeyframeView> keyframes;
  for (int frame = 0; frame <= 200; frame += 20) {
    const core::Isometry pose = loop_scene.cameraPose(frame);
    const auto record = keyframeOf(test::officeFrameAt(loop_scene, pose, frame), pose);
    keyframes.push_back(viewOf(record, static_cast<int>(keyframes.size()), config));
    index.add(keyframes.back().id, record.features->descriptors);
  }
  fusion::PlaceQuery query;
  query.min_votes = config.min_votes;
  query.max_candidates = config.candidates_per_query;

  // The second pass, 1,320 frames later, with its own noise draw.
  const core::Isometry revisit_pose = loop_scene.cameraPose(1400);
  const auto revisit =
      keyframeOf(test::officeFrameAt(loop_scene, revisit_pose, 8401), revisit_pose);
  const auto found =
      index.query(fusion::strongestDescriptors(*revisit.features, config.query_descriptors), query);
  // The loop graph checks the candidates in turn: the first that passes is the place revisited.
  std::string why;
  std::optional<Revisit> checked;
  const KeyframeView* match = nullptr;
  for (const fusion::PlaceCandidate& candidate : found) {
    match = &keyframes[static_cast<std::size_t>(candidate.keyframe)];
    checked = verifyRevisit(*match, viewOf(revisit, 100, config), config, why);
    if (checked) break;
  }
  ASSERT_TRUE(checked.has_value()) << found.size() << " candidates, the last: " << why;
  // Views along the corridor overlap for a few metres: the keyframe need not be the nearest,
  // but its relative pose must be right.
  EXPECT_LT((match->T_W_C.translation() - revisit_pose.translation()).norm(), 2.5)
      << "the keyframe checked does not see the place revisited";
  // The revisit's pose against the truth: 2.6 cm and a fraction of a degree off when written
  // (Kinect v1 depth noise at 1.5-4 m, every 8th pixel).
  const core::Isometry truth = revisit_pose.inverse() * match->T_W_C;
  const core::Isometry error = truth.inverse() * checked->T_query_match;
  EXPECT_LT(error.translation().norm(), 0.04);
  EXPECT_LT(core::rotationAngleDeg(error), 1.0);

  // The north corridor: no candidate passes the check.
  const core::Isometry elsewhere = loop_scene.cameraPose(700);
  const auto distinct = keyframeOf(test::officeFrameAt(loop_scene, elsewhere, 7002), elsewhere);
  for (const fusion::PlaceCandidate& candidate : index.query(
           fusion::strongestDescriptors(*distinct.features, config.query_descriptors), query)) {
    EXPECT_FALSE(verifyRevisit(keyframes[static_cast<std::size_t>(candidate.keyframe)],
                               viewOf(distinct, 101, config), config, why))
        << "a view of the north corridor passed as keyframe " << candidate.keyframe;
  }
}

// A ring of 36 poses 10 degrees apart on a 3 m circle, walked with odometry that turns 0.4
// degrees too far each step; one true loop (last to first) and one wrong loop that claims two
// opposite sides of the ring are the same place.
TEST(PoseGraph, PrunesAnInjectedWrongLoopAndKeepsTheTrueOne) {
  const int n = 36;
  std::vector<core::Isometry> truth;
  for (int i = 0; i < n; ++i) {
    const double a = 2.0 * M_PI * i / n;
    core::Isometry T = core::Isometry::Identity();
    T.linear() = Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    T.translation() = Eigen::Vector3d(3.0 * std::cos(a), 3.0 * std::sin(a), 0.0);
    truth.push_back(T);
  }
  const core::Isometry bias(Eigen::AngleAxisd(0.4 * M_PI / 180.0, Eigen::Vector3d::UnitZ()));
  std::vector<GraphEdge> edges;
  std::vector<core::Isometry> tracked{truth[0]};
  const Matrix6d information = Matrix6d::Identity() * 1e4;
  for (int i = 1; i < n; ++i) {
    const core::Isometry step = truth[i - 1].inverse() * truth[i] * bias;
    tracked.push_back(tracked.back() * step);
    edges.push_back({i - 1, i, step.inverse(), information, false});
  }
  const double drift_before = (tracked[n - 1].translation() - truth[n - 1].translation()).norm();
  ASSERT_GT(drift_before, 0.2);
  edges.push_back({0, n - 1, truth[n - 1].inverse() * truth[0], information, true});  // true
  edges.push_back({9, 27, core::Isometry::Identity(), information, true});            // wrong

  // The first solve's distance: what a 0.3 m + 5 % drift bound allows over the 18 m ring.
  const GraphSolution solution = optimisePoseGraph(tracked, edges, 0.25, 0.3 + 0.05 * 18.0);
  ASSERT_EQ(solution.loop_kept.size(), 2u);
  EXPECT_TRUE(solution.loop_kept[0]) << "the true loop was pruned";
  EXPECT_FALSE(solution.loop_kept[1]) << "the wrong loop was kept";
  double worst = 0.0;
  for (int i = 0; i < n; ++i) {
    worst = std::max(worst, (solution.T_W_C[static_cast<std::size_t>(i)].translation() -
                             truth[static_cast<std::size_t>(i)].translation())
                                .norm());
  }
  EXPECT_LT(worst, 0.25 * drift_before) << "drift at the end before: " << drift_before << " m";
}

// Two passes through the office's first 1.4 m of path, keyframes every 20 frames, each frame
// rendered with its own noise. The second pass is fed as tracked with `offset` added.
struct TwoPasses {
  LoopGraph graph;
  std::vector<core::Isometry> second_truth;
};

// With `restart` the second pass starts a tracking segment (the tracker lost the camera).
void walkTwice(TwoPasses& passes, const core::Isometry& offset, bool restart = false,
               int frame_step = 20) {
  const synthetic::Scene office = scene("office.yaml");
  for (int pass = 0; pass < 2; ++pass) {
    for (int frame = 0; frame <= 100; frame += frame_step) {
      const core::Isometry truth = office.cameraPose(frame);
      const core::Isometry tracked = pass == 0 ? truth : core::Isometry(offset * truth);
      auto record = keyframeOf(test::officeFrameAt(office, truth, 1000 * pass + frame), tracked);
      record.timestamp_ns += pass * 10'000'000'000LL;
      record.starts_segment = restart && pass == 1 && frame == 0;
      passes.graph.add(record);
      if (pass == 1) passes.second_truth.push_back(truth);
    }
  }
  passes.graph.finish();
}

LoopConfig twoPassConfig() {
  LoopConfig config;
  config.min_travel_m = 1.0;  // the office path is short: the second pass starts 1.4 m later
  return config;
}

TEST(LoopGraph, ASecondPassWithDriftClosesTheLoopAndTakesTheDriftOut) {
  // Drift: 12 cm and 2 degrees by the time the walk comes back.
  const core::Isometry drift = core::Isometry(Eigen::Translation3d(0.10, -0.05, 0.04)) *
                               Eigen::AngleAxisd(2.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ());
  TwoPasses passes{LoopGraph(twoPassConfig()), {}};
  walkTwice(passes, drift);
  const LoopStats& stats = passes.graph.stats();
  EXPECT_GE(stats.loop_closures, 2u);
  EXPECT_EQ(stats.rejected_by_graph, 0u);
  const auto& corrected = passes.graph.correctedPoses();
  const std::size_t first_of_second = corrected.size() - passes.second_truth.size();
  for (std::size_t i = 0; i < passes.second_truth.size(); ++i) {
    const double before = (passes.graph.keyframes()[first_of_second + i].T_W_C.translation() -
                           passes.second_truth[i].translation())
                              .norm();
    const double after =
        (corrected[first_of_second + i].translation() - passes.second_truth[i].translation())
            .norm();
    EXPECT_LT(after, 0.03) << "keyframe " << i << " of the second pass, " << before
                           << " m off before";
  }
}

// The error of each second-pass keyframe's corrected position, metres.
std::vector<double> secondPassErrors(const TwoPasses& passes) {
  const auto& corrected = passes.graph.correctedPoses();
  const std::size_t first_of_second = corrected.size() - passes.second_truth.size();
  std::vector<double> errors;
  for (std::size_t i = 0; i < passes.second_truth.size(); ++i) {
    errors.push_back(
        (corrected[first_of_second + i].translation() - passes.second_truth[i].translation())
            .norm());
  }
  return errors;
}

// A revisit is followed up at the next keyframe until another confirms it; then the walk
// through the known place looks itself up at the usual cadence (every 2nd keyframe), not at
// every one, and adds a loop edge at every other keyframe, not at each.
TEST(LoopGraph, AConfirmedRevisitIsFollowedAtTheUsualCadence) {
  const core::Isometry drift = core::Isometry(Eigen::Translation3d(0.10, -0.05, 0.04)) *
                               Eigen::AngleAxisd(2.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ());
  TwoPasses passes{LoopGraph(twoPassConfig()), {}};
  walkTwice(passes, drift, false, 5);  // 21 keyframes a pass
  const LoopStats& stats = passes.graph.stats();
  // Following every revisit verified 6 here and added 6 loop edges.
  EXPECT_GE(stats.loop_closures, 2u);
  EXPECT_LE(stats.revisits_verified, 4u);
  EXPECT_LE(stats.loop_closures, 4u);
  for (const double error : secondPassErrors(passes)) EXPECT_LT(error, 0.03);
}

TEST(LoopGraph, ASegmentAfterALossIsJoinedAcrossAJumpLargerThanTheDriftBound) {
  // Tracking restarted at a guessed pose 1.2 m and 25 degrees off: four times the drift bound
  // (0.3 m + 5 % of the path), and 1.2 m nearer than the travel bound allows a revisit.
  const core::Isometry jump = core::Isometry(Eigen::Translation3d(0.9, 0.6, -0.5)) *
                              Eigen::AngleAxisd(25.0 * M_PI / 180.0, Eigen::Vector3d::UnitY());
  LoopConfig config = twoPassConfig();
  config.min_travel_m = 4.0;
  TwoPasses passes{LoopGraph(config), {}};
  walkTwice(passes, jump, true);
  const LoopStats& stats = passes.graph.stats();
  EXPECT_EQ(stats.segments, 2u);
  EXPECT_EQ(stats.segments_joined, 1u);
  EXPECT_GE(stats.loop_closures, 2u);
  for (const double error : secondPassErrors(passes)) EXPECT_LT(error, 0.03);
  // Joined: every keyframe is in the map, and so is every pose of the trajectory.
  const MapCorrection correction = passes.graph.correction();
  for (const bool in_map : correction.in_map) EXPECT_TRUE(in_map);
  core::Trajectory tracked;
  for (const KeyframeView& key : passes.graph.keyframes()) tracked[key.timestamp_ns] = key.T_W_C;
  EXPECT_EQ(passes.graph.correct(tracked).size(), tracked.size());

  // The same jump without the restart is more than drift: no loop.
  TwoPasses drifted{LoopGraph(config), {}};
  walkTwice(drifted, jump, false);
  EXPECT_EQ(drifted.graph.stats().loop_closures, 0u);
}

// The office's first 1.4 m of path, then tracking restarts and relocalises against the first
// keyframe: the new segment's first keyframe is where the tracker found it, `error` off.
// Returns the graph's figures and whether that keyframe is in the map.
std::pair<LoopStats, bool> relocalisedAfterAWalk(const core::Isometry& error) {
  const synthetic::Scene office = scene("office.yaml");
  LoopConfig config;
  config.min_travel_m = 100.0;  // no revisit by place recognition within one segment
  LoopGraph graph(config);
  for (int frame = 0; frame <= 100; frame += 20) {
    const core::Isometry truth = office.cameraPose(frame);
    auto record = keyframeOf(test::officeFrameAt(office, truth, frame), truth);
    graph.add(record);
  }
  // Where the walk began, seen with other noise.
  const core::Isometry truth = office.cameraPose(0);
  auto record = keyframeOf(test::officeFrameAt(office, truth, 1000), core::Isometry(error * truth));
  record.timestamp_ns += 10'000'000'000LL;
  record.starts_segment = true;
  record.relocalised_against_ns = graph.keyframes().front().timestamp_ns;
  graph.add(record);
  return {graph.stats(), graph.correction().in_map.back()};
}

TEST(LoopGraph, ASegmentTheTrackerRelocalisedIsJoinedAtItsFirstKeyframe) {
  const auto [found, found_in_map] = relocalisedAfterAWalk(core::Isometry::Identity());
  EXPECT_EQ(found.segments, 2u);
  EXPECT_EQ(found.segments_joined, 1u);
  EXPECT_EQ(found.relocalisation_joins, 1u);
  EXPECT_TRUE(found_in_map);

  // A tracker pose 20 cm off the verified one is not taken: the segment stays apart.
  const auto [wrong, wrong_in_map] =
      relocalisedAfterAWalk(core::Isometry(Eigen::Translation3d(0.2, 0.0, 0.0)));
  EXPECT_EQ(wrong.relocalisation_joins, 0u);
  EXPECT_FALSE(wrong_in_map);
}

// Six keyframes along a line, with no features to find a revisit by; tracking restarts at the
// third. That segment is never joined: its poses are not in the map's frame.
TEST(LoopGraph, ASegmentNeverJoinedIsLeftOutOfTheMap) {
  LoopGraph graph{LoopConfig{}};
  core::Trajectory tracked;
  for (int i = 0; i < 6; ++i) {
    fusion::KeyframeRecord record;
    record.timestamp_ns = (i + 1) * 1'000'000'000LL;
    record.T_W_C = core::Isometry(Eigen::Translation3d(0.5 * i, 0.0, 1.5));
    record.depth_m = cv::Mat(16, 16, CV_32F, cv::Scalar(1.5f));
    record.intrinsics = core::Intrinsics{16, 16, 16.0, 16.0, 7.5, 7.5};
    record.starts_segment = i == 2;
    graph.add(record);
    // A pose at each keyframe and one between it and the next.
    tracked[record.timestamp_ns] = record.T_W_C;
    tracked[record.timestamp_ns + 500'000'000] = record.T_W_C;
  }
  tracked[0] = core::Isometry::Identity();  // before the first keyframe
  graph.finish();
  EXPECT_EQ(graph.stats().segments, 2u);
  EXPECT_EQ(graph.stats().segments_joined, 0u);

  const MapCorrection correction = graph.correction();
  EXPECT_EQ(correction.in_map, (std::vector<bool>{true, true, false, false, false, false}));
  EXPECT_TRUE(correction.inMap(0));
  EXPECT_TRUE(correction.inMap(2'900'000'000LL));
  EXPECT_FALSE(correction.inMap(3'000'000'000LL));
  EXPECT_FALSE(correction.inMap(9'000'000'000LL));  // after the newest: follows it

  const core::Trajectory closed = graph.correct(tracked);
  EXPECT_EQ(closed.size(), 5u);  // time 0 and the first two keyframes' poses
  for (const auto& [timestamp_ns, pose] : closed) EXPECT_LT(timestamp_ns, 3'000'000'000LL);
}

TEST(LoopGraph, TwoIdenticalRoomsCloseNoLoop) {
  // The second pass is through an identical room 8 m east: the same views, 8 m from the first.
  const core::Isometry next_door(Eigen::Translation3d(8.0, 0.0, 0.0));
  TwoPasses passes{LoopGraph(twoPassConfig()), {}};
  walkTwice(passes, next_door);
  EXPECT_EQ(passes.graph.stats().loop_closures, 0u);
  EXPECT_TRUE(passes.graph.loops().empty());
}

// Ten laps of a 2 m circle, 48 keyframes a lap, tracked with a little drift: after the first
// lap every keyframe revisits a kept one's place, so the keyframes kept with their features and
// depth (and indexed) stay one lap's, however many laps the walk makes.
TEST(LoopGraph, KeepsOneLapOfKeyframesOverTenLapsOfTheSamePlaces) {
  LoopConfig config;
  config.min_travel_m = 4.0;
  LoopGraph graph(config);
  const int per_lap = 48, laps = 10;
  const cv::Mat depth(16, 16, CV_32F, cv::Scalar(1.5f));
  for (int i = 0; i < per_lap * laps; ++i) {
    const double angle = 2.0 * M_PI * i / per_lap;
    // Looking along the circle; drift of 1 mm a keyframe, up to 5 cm a lap.
    const core::Isometry T_W_C =
        core::Isometry(Eigen::Translation3d(2.0 * std::cos(angle) + 0.001 * (i % per_lap),
                                            2.0 * std::sin(angle), 1.5)) *
        Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ());
    fusion::KeyframeRecord record;
    record.timestamp_ns = static_cast<std::int64_t>(i) * 100'000'000;
    record.T_W_C = T_W_C;
    record.depth_m = depth;
    record.intrinsics = core::Intrinsics{16, 16, 16.0, 16.0, 7.5, 7.5};
    graph.add(record);
  }
  const std::size_t keyframes = graph.keyframes().size();
  EXPECT_EQ(keyframes, static_cast<std::size_t>(per_lap * laps));
  // The first lap, and the first 4 m of the second (the travel bound: min_travel_m).
  EXPECT_LE(graph.keptKeyframes(), static_cast<std::size_t>(per_lap + per_lap / 2));
  EXPECT_EQ(graph.stats().keyframes_covered + graph.keptKeyframes(), keyframes);
  // Covered keyframes let their depth go, all but the newest node.
  std::size_t holding_depth = 0;
  for (const KeyframeView& key : graph.keyframes()) holding_depth += key.depth_m.empty() ? 0 : 1;
  EXPECT_LE(holding_depth, graph.keptKeyframes() + 1);

  // With covering off, every keyframe is kept.
  config.cover_radius_m = 0.0;
  LoopGraph keep_all(config);
  for (const KeyframeView& key : graph.keyframes()) {
    fusion::KeyframeRecord record;
    record.timestamp_ns = key.timestamp_ns;
    record.T_W_C = key.T_W_C;
    record.depth_m = depth;
    record.intrinsics = core::Intrinsics{16, 16, 16.0, 16.0, 7.5, 7.5};
    keep_all.add(record);
  }
  EXPECT_EQ(keep_all.keptKeyframes(), keyframes);
}

}  // namespace
}  // namespace tessera::loop
