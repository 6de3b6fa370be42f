// Colours on real cameras: blended cells, a frame's exposure gain recovered where it overlaps
// the patches, and pixels of something in front of a patch kept out of its colours.
#include <algorithm>
#include <random>
#include <thread>

#include <gtest/gtest.h>

#include "support/synthetic_plane.h"
#include "support/test_data.h"
#include "tessera/planes/colour_samples.h"
#include "tessera/planes/exposure.h"
#include "tessera/planes/patch_map.h"
#include "tessera/texture/bitmap_builder.h"

namespace tessera::planes {
namespace {

TEST(ColourSamples, ACellBlendsItsSamplesByWeightAtTheirWeightedMeanPosition) {
  ColourSamples samples(0.01);
  samples.add(0.002F, 0.002F, {100, 0, 200}, 1.0F);
  samples.add(0.006F, 0.004F, {200, 100, 0}, 3.0F);
  ASSERT_EQ(samples.size(), 1u);
  const std::vector<ColourSample> all = samples.all();
  ASSERT_EQ(all.size(), 1u);
  EXPECT_EQ(all[0].rgb, (std::array<std::uint8_t, 3>{175, 75, 50}));
  EXPECT_NEAR(all[0].u, 0.005F, 0.0001F);
  EXPECT_NEAR(all[0].v, 0.0035F, 0.0001F);
  EXPECT_NEAR(std::exp(all[0].score), 4.0F, 1e-4F);
  EXPECT_TRUE(samples.colourAt(0.009F, 0.001F).has_value());
  EXPECT_FALSE(samples.colourAt(0.011F, 0.001F).has_value());
  EXPECT_FALSE(samples.colourAt(-0.001F, 0.001F).has_value());
  // 32 x 32 cells of 12 bytes are allocated as a tile is touched.
  EXPECT_EQ(samples.bytes(), 32u * 32u * 12u);
}

// bytes() counts the layers as they come and go: views kept apart, the lightest dropped, the
// samples copied, moved, and saved and read back.
TEST(ColourSamples, BytesFollowTheLayersThroughSettlingCopiesAndFiles) {
  constexpr std::size_t kLayerBytes = 32u * 32u * 12u;
  ColourSamples samples(0.01, 2);  // two views kept per tile
  for (std::int32_t view = 0; view < 3; ++view) {
    samples.add(0.005F, 0.005F, {10, 20, 30}, 1.0F + static_cast<float>(view), view);
    samples.add(0.5F, 0.005F, {10, 20, 30}, 1.0F, view);  // a second tile
  }
  EXPECT_EQ(samples.bytes(), 6 * kLayerBytes);
  samples.settle();  // each tile keeps its two heaviest views
  EXPECT_EQ(samples.bytes(), 4 * kLayerBytes);
  const ColourSamples copy = samples;
  EXPECT_EQ(copy.bytes(), 4 * kLayerBytes);
  ColourSamples moved = std::move(samples);
  EXPECT_EQ(moved.bytes(), 4 * kLayerBytes);
  EXPECT_EQ(samples.bytes(), 0u);  // NOLINT(bugprone-use-after-move): moved-from is empty
  const std::filesystem::path file = test::freshTempDir() / "samples.bin";
  moved.save(file);
  EXPECT_EQ(ColourSamples::load(file).bytes(), 4 * kLayerBytes);
}

// The per-pixel path locates cells ahead of blending them; each cell must end as add() one by
// one leaves it, also where locating makes new tiles and layers (views kept apart) first.
TEST(ColourSamples, LocatingAheadAndBlendingLaterLeavesTheCellsAsAddingOneByOne) {
  std::mt19937 random(11);
  std::uniform_real_distribution<float> position(-0.3F, 0.3F), weight(0.1F, 5.0F);
  std::uniform_int_distribution<int> level(0, 255), view(0, 5);
  for (const int views : {0, 2}) {
    ColourSamples one_by_one(0.0035, views), ahead(0.0035, views);
    struct Pending {
      ColourSamples::Slot slot;
      std::array<std::uint8_t, 3> rgb;
      float weight;
    };
    std::vector<Pending> queue;
    constexpr std::size_t kAhead = 7;
    float row_u = 0.0F, row_v = 0.0F;
    for (int i = 0; i < 20000; ++i) {
      // Runs of neighbouring pixels about a cell apart, as an image row gives, with jumps
      // between them; some land in a cell already blended.
      if (i % 50 == 0) row_u = position(random), row_v = position(random);
      const float u = row_u + 0.003F * static_cast<float>(i % 50);
      const float v = row_v + 0.001F * position(random);
      const std::array<std::uint8_t, 3> rgb{static_cast<std::uint8_t>(level(random)),
                                            static_cast<std::uint8_t>(level(random)),
                                            static_cast<std::uint8_t>(level(random))};
      const float w = weight(random);
      const int frame = views == 0 ? -1 : view(random);
      one_by_one.add(u, v, rgb, w, frame);
      queue.push_back({ahead.locate(u, v, frame), rgb, w});
      if (queue.size() > kAhead) {
        ahead.blend(queue.front().slot, queue.front().rgb, queue.front().weight);
        queue.erase(queue.begin());
      }
    }
    for (const Pending& left : queue) ahead.blend(left.slot, left.rgb, left.weight);
    one_by_one.settle();
    ahead.settle();
    const std::vector<ColourSample> expected = one_by_one.all(), got = ahead.all();
    ASSERT_EQ(got.size(), expected.size()) << views << " views";
    EXPECT_GT(got.size(), 1000u);
    for (std::size_t i = 0; i < got.size(); ++i) {
      ASSERT_EQ(got[i].u, expected[i].u) << i;
      ASSERT_EQ(got[i].v, expected[i].v) << i;
      ASSERT_EQ(got[i].rgb, expected[i].rgb) << i;
      ASSERT_EQ(got[i].score, expected[i].score) << i;
      ASSERT_EQ(got[i].view, expected[i].view) << i;
    }
  }
}

TEST(Exposure, GainIsRecoveredDespiteOutliersAndClippedPixels) {
  std::mt19937 random(3);
  std::uniform_real_distribution<float> level(50.0F, 200.0F);
  std::normal_distribution<float> noise(0.0F, 2.0F);
  const Eigen::Vector3f gain(1.25F, 0.9F, 1.1F);
  std::vector<ColourPair> pairs;
  for (int i = 0; i < 3000; ++i) {
    const Eigen::Vector3f reference(level(random), level(random), level(random));
    Eigen::Vector3f observed = reference.cwiseQuotient(gain);
    for (int c = 0; c < 3; ++c) observed[c] += noise(random);
    if (i % 5 == 0) observed = Eigen::Vector3f(250.0F, 30.0F, 90.0F);  // a highlight, misplaced
    pairs.push_back({observed, reference});
  }
  const auto estimated = estimateGain(pairs);
  ASSERT_TRUE(estimated.has_value());
  EXPECT_NEAR((*estimated)[0], 1.25F, 0.01F);
  EXPECT_NEAR((*estimated)[1], 0.9F, 0.01F);
  EXPECT_NEAR((*estimated)[2], 1.1F, 0.01F);
  EXPECT_FALSE(estimateGain({pairs.begin(), pairs.begin() + 50}).has_value());  // too few
}

// A textured wall 2 m away seen from five poses, each frame with its own known exposure: the
// gain the map applies to frame k is its exposure relative to the first frame's.
TEST(Exposure, KnownPerFrameGainsOfARenderedSequenceAreRecovered) {
  const std::vector<Eigen::Vector3f> exposures = {{1.0F, 1.0F, 1.0F},
                                                  {0.8F, 0.85F, 0.75F},
                                                  {1.1F, 1.05F, 1.1F},
                                                  {0.7F, 0.7F, 0.8F},
                                                  {0.9F, 1.1F, 1.0F}};
  PatchMapConfig config;
  config.exposure_compensation = true;
  PatchMap map(config);
  const PlaneDetector detector(PlaneDetectorConfig{});
  for (std::size_t k = 0; k < exposures.size(); ++k) {
    core::Isometry T_W_C = core::Isometry::Identity();
    T_W_C.translation() = Eigen::Vector3d(0.1 * static_cast<double>(k), 0.02, 0.0);
    core::Frame frame =
        test::renderPlane(test::kinectIntrinsics(), T_W_C, Eigen::Vector3d(0, 0, -1), -2.0);
    // The board's light squares (220, 200, 180) get the frame's exposure; its dark ones are too
    // dark to measure gain with and stay as they are.
    frame.rgb.forEach<cv::Vec3b>([&](cv::Vec3b& rgb, const int*) {
      if (rgb[0] < 100) return;
      for (int c = 0; c < 3; ++c)
        rgb[c] = cv::saturate_cast<std::uint8_t>(exposures[k][c] * rgb[c]);
    });
    const PlaneDetection detection = detector.detect(frame);
    const auto ids = map.add(observationsOf(frame, detection, T_W_C));
    const auto gain = map.addColours(frame, detection, T_W_C, ids);
    ASSERT_TRUE(gain.has_value()) << "frame " << k;
    for (int c = 0; c < 3; ++c) {
      // Colours are 8-bit: a gain is known to about one grey level in 200.
      EXPECT_NEAR((*gain)[c], exposures[0][c] / exposures[k][c], 0.015F) << "frame " << k;
    }
  }
}

// A wall 2 m away with a red box face 1.2 m in front of it. Even when the plane detector puts
// the box's pixels into the wall's region, the measured depth says they are not the wall, so
// none of them colours it, and the wall's bitmap shows no red.
TEST(PatchColours, PixelsOfAnOccluderNeverReachThePatchBehindIt) {
  const core::Isometry T_W_C = core::Isometry::Identity();
  core::Frame wall =
      test::renderPlane(test::kinectIntrinsics(), T_W_C, Eigen::Vector3d(0, 0, -1), -2.0);
  wall.rgb.setTo(cv::Scalar(200, 200, 200));
  const PlaneDetector detector(PlaneDetectorConfig{});
  PatchMap map(PatchMapConfig{});
  const PlaneDetection clean = detector.detect(wall);
  ASSERT_EQ(clean.planes.size(), 1u);
  const std::vector<int> ids = map.add(observationsOf(wall, clean, T_W_C));

  core::Frame occluded = wall;
  const core::Intrinsics& k = occluded.intrinsics;
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const double x = (u - k.cx) / k.fx * 0.8, y = (v - k.cy) / k.fy * 0.8;
      if (std::abs(x) > 0.2 || std::abs(y) > 0.2) continue;
      occluded.depth_mm.at<std::uint16_t>(v, u) = 800;
      occluded.rgb.at<cv::Vec3b>(v, u) = cv::Vec3b(255, 0, 0);
    }
  }
  PlaneDetection everything_wall = clean;
  everything_wall.labels.setTo(0);  // the box's pixels too
  map.addColours(occluded, everything_wall, T_W_C, ids);

  const Patch& patch = map.patches().front();
  const std::vector<ColourSample> samples = patch.samples->all();
  ASSERT_GT(samples.size(), 10000u);
  for (const ColourSample& sample : samples) {
    ASSERT_EQ(sample.rgb, (std::array<std::uint8_t, 3>{200, 200, 200}))
        << "at (" << sample.u << ", " << sample.v << ")";
  }
  const texture::PatchBitmap bitmap = texture::buildBitmap(map.snapshot(patch), {});
  ASSERT_GT(bitmap.observed, 1000u);
  cv::Mat red;
  cv::inRange(bitmap.image, cv::Scalar(230, 0, 0), cv::Scalar(255, 180, 180), red);
  EXPECT_EQ(cv::countNonZero(red), 0);
}

// A grey (200) wall 2 m in front of the camera, its patch in `map` coloured once; colour()
// colours it again from the same view with another grey.
struct GreyWall {
  explicit GreyWall(PatchMap& into) : map(into) {
    frame.rgb.setTo(cv::Scalar(200, 200, 200));
    detection = PlaneDetector(PlaneDetectorConfig{}).detect(frame);
    ids = map.add(observationsOf(frame, detection, T_W_C));
    map.addColours(frame, detection, T_W_C, ids);
  }
  void colour(std::uint8_t grey) {
    frame.rgb.setTo(cv::Scalar(grey, grey, grey));
    map.addColours(frame, detection, T_W_C, ids);
  }

  PatchMap& map;
  core::Isometry T_W_C = core::Isometry::Identity();
  core::Frame frame =
      test::renderPlane(test::kinectIntrinsics(), T_W_C, Eigen::Vector3d(0, 0, -1), -2.0);
  PlaneDetection detection;
  std::vector<int> ids;
};

// A snapshot shares the patch's samples instead of copying them; colours the patch takes
// afterwards go to a copy the patch makes then, so the snapshot lists what it was taken with.
// With no snapshot left holding them, the patch changes its samples in place.
TEST(PatchColours, ASnapshotKeepsItsSamplesWhileThePatchTakesMoreColour) {
  PatchMap map(PatchMapConfig{});
  GreyWall wall(map);
  ASSERT_EQ(wall.detection.planes.size(), 1u);
  const Patch& patch = map.patches().front();
  PatchSnapshot snapshot = map.snapshot(patch);
  ASSERT_EQ(snapshot.shared_samples.get(), &*patch.samples);  // shared, not copied
  const std::size_t taken = sampleCount(snapshot);
  ASSERT_GT(taken, 10000u);

  wall.colour(100);
  EXPECT_NE(snapshot.shared_samples.get(), &*patch.samples);
  const std::vector<ColourSample> listed = sampleList(snapshot);
  ASSERT_EQ(listed.size(), taken);
  for (const ColourSample& sample : listed) {
    ASSERT_EQ(sample.rgb, (std::array<std::uint8_t, 3>{200, 200, 200}));
  }
  const std::vector<ColourSample> now = patch.samples->all();
  ASSERT_FALSE(now.empty());
  EXPECT_NEAR(now.front().rgb[0], 150, 2);  // both frames, blended

  snapshot = {};
  const ColourSamples* own = &*patch.samples;
  wall.colour(100);
  EXPECT_EQ(&*patch.samples, own);
}

// The describing thread lists a snapshot's samples while the map thread goes on colouring the
// patch: the listing sees the colours of the snapshot's time only (under the sanitizers, also
// that no sample it reads is freed or changed under it).
TEST(PatchColours, ASnapshotIsListedOnAnotherThreadWhileThePatchChanges) {
  PatchMap map(PatchMapConfig{});
  GreyWall wall(map);
  ASSERT_EQ(wall.detection.planes.size(), 1u);
  auto snapshot = std::make_shared<const PatchSnapshot>(map.snapshot(map.patches().front()));
  const std::size_t taken = sampleCount(*snapshot);

  std::size_t wrong = 0, listed = 0;
  std::thread describer([snapshot = std::move(snapshot), &wrong, &listed]() mutable {
    for (int round = 0; round < 5; ++round) {
      for (const ColourSample& sample : sampleList(*snapshot)) {
        wrong += sample.rgb == std::array<std::uint8_t, 3>{200, 200, 200} ? 0 : 1;
        ++listed;
      }
    }
    snapshot.reset();  // let go while the map may be changing the patch
  });
  for (int round = 0; round < 5; ++round) wall.colour(100);
  describer.join();
  EXPECT_EQ(listed, 5 * taken);
  EXPECT_EQ(wrong, 0u);
  EXPECT_LT(map.patches().front().samples->all().front().rgb[0], 150);
}

// The colour image taken 2 cm to the right of where the depth image was (an unsynchronised
// Kinect v1 while the camera moves): placed with the colour's own pose, each sample has the
// board's colour at its position; placed with the depth's pose, a 2 cm strip at every edge of
// the board's squares has the neighbouring square's colour.
TEST(PatchColours, ColourTakenAtAnotherPoseIsPlacedWithThatPose) {
  const core::Isometry T_W_depth = core::Isometry::Identity();
  core::Isometry T_W_colour = core::Isometry::Identity();
  T_W_colour.translation() = Eigen::Vector3d(0.02, 0.0, 0.0);
  const Eigen::Vector3d n(0, 0, -1);
  core::Frame frame = test::renderPlane(test::kinectIntrinsics(), T_W_depth, n, -2.0);
  frame.rgb = test::renderPlane(test::kinectIntrinsics(), T_W_colour, n, -2.0).rgb;
  const PlaneDetector detector(PlaneDetectorConfig{});
  const PlaneDetection detection = detector.detect(frame);
  ASSERT_EQ(detection.planes.size(), 1u);
  const auto misplacedShare = [&](const std::optional<core::Isometry>& colour_pose) {
    PatchMap map(PatchMapConfig{});
    const std::vector<int> ids = map.add(observationsOf(frame, detection, T_W_depth));
    map.addColours(frame, detection, T_W_depth, ids, 1.0, colour_pose);
    const Patch& patch = map.patches().front();
    const Patch::Frame plane = patch.planeFrame();
    std::size_t wrong = 0, total = 0;
    for (const ColourSample& s : patch.samples->all()) {
      const Eigen::Vector3d X = plane.origin + s.u * plane.u_axis + s.v * plane.v_axis;
      const long squares = static_cast<long>(std::floor(X.x() * 10)) +
                           static_cast<long>(std::floor(X.y() * 10)) +
                           static_cast<long>(std::floor(X.z() * 10));
      const std::uint8_t want = squares % 2 != 0 ? 40 : 220;
      wrong += std::abs(static_cast<int>(s.rgb[0]) - want) > 60 ? 1 : 0;
      ++total;
    }
    return static_cast<double>(wrong) / static_cast<double>(std::max<std::size_t>(total, 1));
  };
  EXPECT_LT(misplacedShare(T_W_colour), 0.03);
  EXPECT_GT(misplacedShare(std::nullopt), 0.1);
}

// One wall fitted twice, as noisy depth does: a second plane 8 degrees off it (beyond the 5 a
// region continues a patch within) crosses it at x = 0. A frame of the wall whose region
// continues the first plane colours the second too, but only where the wall's depth confirms
// the second plane, near the crossing; with colour_neighbour_angle_deg 0 it does not.
TEST(PatchColours, APlaneNearTheRegionsOwnIsColouredWhereTheDepthConfirmsIt) {
  const core::Isometry T_W_C = core::Isometry::Identity();
  const Eigen::Vector3d wall_n(0, 0, -1);
  const Eigen::Vector3d tilted_n =
      Eigen::AngleAxisd(8.0 * M_PI / 180.0, Eigen::Vector3d::UnitY()) * wall_n;
  core::Frame wall = test::renderPlane(test::kinectIntrinsics(), T_W_C, wall_n, -2.0);
  wall.rgb.setTo(cv::Scalar(200, 200, 200));
  const core::Frame tilted = test::renderPlane(test::kinectIntrinsics(), T_W_C, tilted_n,
                                               tilted_n.dot(Eigen::Vector3d(0, 0, 2)));
  const PlaneDetector detector(PlaneDetectorConfig{});
  const PlaneDetection wall_detection = detector.detect(wall);
  const PlaneDetection tilted_detection = detector.detect(tilted);
  ASSERT_EQ(wall_detection.planes.size(), 1u);
  ASSERT_EQ(tilted_detection.planes.size(), 1u);
  const auto samplesOnTilted = [&](double neighbour_angle_deg) {
    PatchMapConfig config;
    config.colour_neighbour_angle_deg = neighbour_angle_deg;
    PatchMap map(config);
    const std::vector<int> wall_ids = map.add(observationsOf(wall, wall_detection, T_W_C));
    map.add(observationsOf(tilted, tilted_detection, T_W_C));
    EXPECT_EQ(map.patches().size(), 2u) << "the tilted plane continued the wall";
    map.addColours(wall, wall_detection, T_W_C, wall_ids);
    const Patch& own = *std::find_if(map.patches().begin(), map.patches().end(),
                                     [&](const Patch& p) { return p.id == wall_ids.front(); });
    EXPECT_GT(own.samples->all().size(), 10000u);
    std::vector<ColourSample> on_tilted;
    for (const Patch& patch : map.patches()) {
      if (patch.id == wall_ids.front()) continue;
      const Patch::Frame plane = patch.planeFrame();
      for (const ColourSample& s : patch.samples->all()) {
        on_tilted.push_back(s);
        // Near the crossing: the wall is within the colour depth tolerance (1 cm + 0.005 z^2,
        // 3 cm at 2 m) of the tilted plane only for |x| up to 3 cm / tan 8 degrees, 21 cm.
        const Eigen::Vector3d X = plane.origin + s.u * plane.u_axis + s.v * plane.v_axis;
        EXPECT_LT(std::abs(X.x()), 0.23) << "coloured far from where the depth confirms it";
        EXPECT_EQ(s.rgb, (std::array<std::uint8_t, 3>{200, 200, 200}));
      }
    }
    return on_tilted.size();
  };
  EXPECT_GT(samplesOnTilted(15.0), 2000u);
  EXPECT_EQ(samplesOnTilted(0.0), 0u);
}

}  // namespace
}  // namespace tessera::planes
