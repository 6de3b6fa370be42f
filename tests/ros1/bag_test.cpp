// ROS 1 bags: written by BagWriter or by hand with librosbag, read back by the bag source.
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>
#include <random>

#include <fmt/format.h>
#include <geometry_msgs/PoseStamped.h>
#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <tf2_msgs/TFMessage.h>
#include <opencv2/core.hpp>

#include "support/test_data.h"
#include "tessera/core/error.h"
#include "tessera/drivers/dataset_source.h"
#include "tessera/drivers/ros1/bag_source.h"
#include "tessera/drivers/ros1/bag_writer.h"
#include "tessera/drivers/ros1/ros_image.h"

namespace tessera::drivers::ros1 {
namespace {

namespace fs = std::filesystem;

core::Intrinsics smallCamera() {
  core::Intrinsics k;
  k.width = 160, k.height = 120, k.fx = 130.0, k.fy = 131.0, k.cx = 79.5, k.cy = 60.5;
  return k;
}

// Seeded random depth (with holes) and colour, stamps 33 ms apart from 1 s, colour 7 ms
// later, and a ground-truth pose moving along x and turning about y.
std::vector<core::Frame> randomFrames(int count) {
  std::mt19937 rng(42);
  std::uniform_int_distribution<int> depth(0, 9000);
  std::vector<core::Frame> frames;
  for (int i = 0; i < count; ++i) {
    core::Frame frame;
    frame.index = static_cast<std::uint64_t>(i);
    frame.timestamp_ns = 1'000'000'000LL + i * 33'000'000LL;
    frame.colour_timestamp_ns = frame.timestamp_ns + 7'000'000;
    frame.intrinsics = smallCamera();
    frame.depth_mm.create(120, 160, CV_16UC1);
    for (auto it = frame.depth_mm.begin<std::uint16_t>(); it != frame.depth_mm.end<std::uint16_t>();
         ++it) {
      *it = static_cast<std::uint16_t>(depth(rng) < 500 ? 0 : depth(rng));
    }
    frame.rgb.create(120, 160, CV_8UC3);
    cv::randu(frame.rgb, 0, 256);
    core::Isometry T_W_C = core::Isometry::Identity();
    T_W_C.translation() = Eigen::Vector3d(0.05 * i, 0.3, 1.2);
    T_W_C.linear() = Eigen::AngleAxisd(0.02 * i, Eigen::Vector3d::UnitY()).toRotationMatrix();
    frame.T_W_C_gt = T_W_C;
    frames.push_back(std::move(frame));
  }
  return frames;
}

void writeBag(const fs::path& path, const std::vector<core::Frame>& frames,
              const BagWriterOptions& options = {}) {
  BagWriter writer(path, options);
  for (const core::Frame& frame : frames) writer.write(frame);
  writer.close();
}

struct Played {
  std::vector<core::Frame> frames;
  std::vector<std::string> bad;
  std::string end_problem;
};

Played playAll(core::FrameSource& source) {
  Played played;
  for (;;) {
    core::ReadResult result = source.read();
    if (result.status == core::ReadStatus::kEndOfData) {
      played.end_problem = result.problem;
      return played;
    }
    if (result.status == core::ReadStatus::kFrame) played.frames.push_back(std::move(result.frame));
    if (result.status == core::ReadStatus::kBadFrame) played.bad.push_back(result.problem);
  }
}

bool identical(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0.0;
}

// `played` holds frames of `written` (matched by stamp), each identical to it.
void expectSameFrames(const std::vector<core::Frame>& played,
                      const std::vector<core::Frame>& written, double pose_tolerance = 1e-9,
                      bool cut_off = false) {
  for (const core::Frame& frame : played) {
    const auto original = std::find_if(written.begin(), written.end(), [&](const core::Frame& w) {
      return w.timestamp_ns == frame.timestamp_ns;
    });
    ASSERT_NE(original, written.end()) << "a frame at an unknown stamp " << frame.timestamp_ns;
    EXPECT_TRUE(identical(frame.depth_mm, original->depth_mm)) << frame.timestamp_ns;
    EXPECT_TRUE(identical(frame.rgb, original->rgb)) << frame.timestamp_ns;
    EXPECT_EQ(frame.colour_timestamp_ns, original->colour_timestamp_ns);
    // A cut-off bag may lose the last frame's pose: it is written after the images.
    if (&frame == &played.back() && !frame.T_W_C_gt && cut_off) continue;
    ASSERT_TRUE(frame.T_W_C_gt.has_value());
    EXPECT_LT((frame.T_W_C_gt->matrix() - original->T_W_C_gt->matrix()).norm(), pose_tolerance);
  }
}

std::string messageOf(const std::function<void()>& action) {
  try {
    action();
  } catch (const core::Error& e) {
    return e.what();
  }
  return "";
}

TEST(Ros1Bag, RoundTripKeepsDepthColourStampsPosesAndIntrinsics) {
  const fs::path dir = test::freshTempDir();
  const auto frames = randomFrames(12);
  for (const char* depth_encoding : {"16UC1", "32FC1"}) {
    for (const bool lz4 : {false, true}) {
      BagWriterOptions options;
      options.depth_encoding = depth_encoding;
      options.lz4 = lz4;
      const fs::path bag = dir / fmt::format("frames_{}_{}.bag", depth_encoding, lz4);
      writeBag(bag, frames, options);
      auto source = openBagSource(bag);
      EXPECT_EQ(source->frameCount(), 12u);
      const Played played = playAll(*source);
      ASSERT_EQ(played.frames.size(), 12u) << depth_encoding;
      EXPECT_TRUE(played.bad.empty());
      EXPECT_TRUE(played.end_problem.empty()) << played.end_problem;
      expectSameFrames(played.frames, frames);
      for (std::size_t i = 0; i < played.frames.size(); ++i) {
        EXPECT_EQ(played.frames[i].index, i);
        EXPECT_EQ(played.frames[i].timestamp_ns, frames[i].timestamp_ns);
        EXPECT_DOUBLE_EQ(played.frames[i].intrinsics.fx, 130.0);
        EXPECT_DOUBLE_EQ(played.frames[i].intrinsics.cy, 60.5);
        EXPECT_FALSE(played.frames[i].colour_camera.has_value());
      }
    }
  }
}

// Robots record image_transport's compressed topics: lossless PNG plays back the very frames,
// JPEG the same depth; the topics are found under the known sets' names.
TEST(Ros1Bag, CompressedTopicsPlayBackAsTheRawOnesDo) {
  const fs::path dir = test::freshTempDir();
  const auto frames = randomFrames(6);
  for (const char* format : {"png", "jpeg"}) {
    BagWriterOptions options;
    options.compressed = format;
    const fs::path bag = dir / fmt::format("compressed_{}.bag", format);
    writeBag(bag, frames, options);
    {
      rosbag::Bag written(bag.string(), rosbag::bagmode::Read);
      rosbag::View raw(written, rosbag::TopicQuery(openniLaunchTopics().depth));
      EXPECT_EQ(raw.size(), 0u) << "raw depth written beside the compressed";
      rosbag::View compressed(written,
                              rosbag::TopicQuery(openniLaunchTopics().depth + "/compressedDepth"));
      EXPECT_EQ(compressed.size(), 6u);
    }
    auto source = openBagSource(bag);
    EXPECT_EQ(source->frameCount(), 6u);
    const Played played = playAll(*source);
    ASSERT_EQ(played.frames.size(), 6u) << format;
    EXPECT_TRUE(played.bad.empty());
    if (std::string(format) == "png") {
      expectSameFrames(played.frames, frames);
    } else {
      for (std::size_t i = 0; i < played.frames.size(); ++i) {
        EXPECT_TRUE(identical(played.frames[i].depth_mm, frames[i].depth_mm));
        EXPECT_EQ(played.frames[i].rgb.size(), frames[i].rgb.size());
      }
    }
  }
  BagWriterOptions metric;
  metric.compressed = "png";
  metric.depth_encoding = "32FC1";
  EXPECT_THROW(BagWriter(dir / "metric.bag", metric), core::ConfigError);
}

// Writes image `i` of a hand-made bag: depth 1000 + i mm, colour value 10 i.
void writeImage(rosbag::Bag& bag, const std::string& topic, bool depth, int i,
                std::int64_t stamp_ns, std::int64_t record_ns) {
  sensor_msgs::Image image =
      depth ? imageFromDepth(cv::Mat(120, 160, CV_16UC1, cv::Scalar(1000 + i)), "16UC1")
            : imageFromColour(cv::Mat(120, 160, CV_8UC3, cv::Scalar::all(10 * i)), "rgb8");
  image.header.stamp.fromNSec(static_cast<std::uint64_t>(stamp_ns));
  image.header.frame_id = "camera";
  ros::Time record;
  record.fromNSec(static_cast<std::uint64_t>(record_ns));
  bag.write(topic, record, image);
  if (depth) {
    sensor_msgs::CameraInfo info = cameraInfoFromIntrinsics(smallCamera());
    info.header = image.header;
    bag.write(openniLaunchTopics().depth_info, record, info);
  }
}

TEST(Ros1Bag, PairsByStampThroughJitterReorderingAndAMissingColourImage) {
  const fs::path path = test::freshTempDir() / "jitter.bag";
  const RosTopics topics = openniLaunchTopics();
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> jitter_ms(-8, 8);
  std::uniform_int_distribution<int> delay_ms(0, 60);
  std::map<int, std::int64_t> colour_stamps;
  {
    rosbag::Bag bag(path.string(), rosbag::bagmode::Write);
    for (int i = 0; i < 12; ++i) {
      const std::int64_t depth_ns = 2'000'000'000LL + i * 33'333'333LL;
      writeImage(bag, topics.depth, true, i, depth_ns, depth_ns + 1'000'000);
      if (i == 5) continue;  // the colour image that never came
      const std::int64_t colour_ns = depth_ns + jitter_ms(rng) * 1'000'000LL;
      colour_stamps[i] = colour_ns;
      // The recorder receives colour late, by up to two frames: record order is not stamp order.
      writeImage(bag, topics.colour, false, i, colour_ns, colour_ns + delay_ms(rng) * 1'000'000LL);
    }
    bag.close();
  }
  auto source = openBagSource(path);
  const Played played = playAll(*source);
  ASSERT_EQ(played.frames.size(), 11u);
  ASSERT_EQ(played.bad.size(), 1u);
  EXPECT_NE(played.bad[0].find("no colour image within 20 ms"), std::string::npos) << played.bad[0];
  for (const core::Frame& frame : played.frames) {
    const int i = frame.depth_mm.at<std::uint16_t>(0, 0) - 1000;
    EXPECT_NE(i, 5);
    EXPECT_EQ(frame.rgb.at<cv::Vec3b>(0, 0)[0], 10 * i) << "depth " << i << " got another colour";
    EXPECT_EQ(frame.colour_timestamp_ns, colour_stamps[i]);
  }
}

TEST(Ros1Bag, GroundTruthFromATfChainAndFromAPoseTopic) {
  const fs::path path = test::freshTempDir() / "poses.bag";
  const RosTopics topics = openniLaunchTopics();
  // world -> base moves 1 m/s along x, sampled at 100 Hz; base -> camera is a fixed mount.
  core::Isometry T_base_camera = core::Isometry::Identity();
  T_base_camera.translation() = Eigen::Vector3d(0.1, 0.0, 0.5);
  T_base_camera.linear() =
      Eigen::AngleAxisd(-M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const auto T_world_base = [](std::int64_t t_ns) {
    core::Isometry T = core::Isometry::Identity();
    T.translation().x() = static_cast<double>(t_ns) * 1e-9;
    return T;
  };
  const auto transform = [](const core::Isometry& T) {
    geometry_msgs::Transform t;
    const Eigen::Quaterniond q(T.rotation());
    t.translation.x = T.translation().x(), t.translation.y = T.translation().y();
    t.translation.z = T.translation().z();
    t.rotation.x = q.x(), t.rotation.y = q.y(), t.rotation.z = q.z(), t.rotation.w = q.w();
    return t;
  };
  {
    rosbag::Bag bag(path.string(), rosbag::bagmode::Write);
    ros::Time start;
    start.fromNSec(1'000'000'000);
    tf2_msgs::TFMessage mount;
    mount.transforms.resize(1);
    mount.transforms[0].header.frame_id = "base";
    mount.transforms[0].child_frame_id = "camera";
    mount.transforms[0].transform = transform(T_base_camera);
    bag.write("/tf_static", start, mount);
    for (std::int64_t t = 1'000'000'000; t <= 1'500'000'000; t += 10'000'000) {
      ros::Time stamp;
      stamp.fromNSec(static_cast<std::uint64_t>(t));
      tf2_msgs::TFMessage moving;
      moving.transforms.resize(1);
      moving.transforms[0].header.stamp = stamp;
      moving.transforms[0].header.frame_id = "/world";  // tf1 style
      moving.transforms[0].child_frame_id = "base";
      moving.transforms[0].transform = transform(T_world_base(t));
      bag.write("/tf", stamp, moving);
      geometry_msgs::PoseStamped pose;
      pose.header = moving.transforms[0].header;
      const core::Isometry T_world_camera = T_world_base(t) * T_base_camera;
      pose.pose.position.x = T_world_camera.translation().x();
      pose.pose.position.y = T_world_camera.translation().y();
      pose.pose.position.z = T_world_camera.translation().z();
      const Eigen::Quaterniond q(T_world_camera.rotation());
      pose.pose.orientation.x = q.x(), pose.pose.orientation.y = q.y();
      pose.pose.orientation.z = q.z(), pose.pose.orientation.w = q.w();
      bag.write("/mocap/pose", stamp, pose);
    }
    for (int i = 0; i < 10; ++i) {
      // Between the 100 Hz samples: the poses are interpolated.
      const std::int64_t t = 1'103'000'000LL + i * 33'000'000LL;
      writeImage(bag, topics.depth, true, i, t, t);
      writeImage(bag, topics.colour, false, i, t + 2'000'000, t + 2'000'000);
    }
    bag.close();
  }
  for (const bool from_pose_topic : {false, true}) {
    BagSourceOptions options;
    if (from_pose_topic) {
      options.topics = openniLaunchTopics();
      options.topics->pose = "/mocap/pose";
      options.pose_named = true;
    }
    auto source = openBagSource(path, options);
    const Played played = playAll(*source);
    ASSERT_EQ(played.frames.size(), 10u);
    for (const core::Frame& frame : played.frames) {
      ASSERT_TRUE(frame.T_W_C_gt.has_value()) << from_pose_topic;
      const core::Isometry expected = T_world_base(frame.timestamp_ns) * T_base_camera;
      EXPECT_LT((frame.T_W_C_gt->matrix() - expected.matrix()).norm(), 1e-9) << from_pose_topic;
    }
  }
  BagSourceOptions wrong_world;
  wrong_world.world_frame = "map";
  auto source = openBagSource(path, wrong_world);
  const Played played = playAll(*source);
  ASSERT_EQ(played.frames.size(), 10u);
  EXPECT_FALSE(played.frames[0].T_W_C_gt.has_value()) << "no chain from camera to 'map'";
}

TEST(Ros1Bag, ABagWithoutTheTopicsListsTheTopicsItHas) {
  const fs::path dir = test::freshTempDir();
  BagWriterOptions options;
  options.topics.depth = "/kinect/depth/image_raw";
  options.topics.colour = "/kinect/rgb/image_raw";
  writeBag(dir / "renamed.bag", randomFrames(3), options);
  const std::string message = messageOf([&] { openBagSource(dir / "renamed.bag"); });
  EXPECT_NE(message.find("renamed.bag"), std::string::npos) << message;
  EXPECT_NE(message.find("/kinect/depth/image_raw (sensor_msgs/Image, 3 messages)"),
            std::string::npos)
      << message;
  EXPECT_NE(message.find("--topic depth:="), std::string::npos) << message;
  // Named, they play.
  BagSourceOptions named;
  named.topics = options.topics;
  auto source = openBagSource(dir / "renamed.bag", named);
  EXPECT_EQ(playAll(*source).frames.size(), 3u);
  // A named pose topic that is not there is an error too.
  named.topics->pose = "/vicon";
  named.pose_named = true;
  EXPECT_NE(messageOf([&] { openBagSource(dir / "renamed.bag", named); }).find("/vicon"),
            std::string::npos);
}

TEST(Ros1Bag, AColourTopicInAnEncodingNotReadEndsWithOneError) {
  const fs::path path = test::freshTempDir() / "jpeg.bag";
  const RosTopics topics = openniLaunchTopics();
  {
    rosbag::Bag bag(path.string(), rosbag::bagmode::Write);
    for (int i = 0; i < 8; ++i) {
      const std::int64_t t = 1'000'000'000LL + i * 33'000'000LL;
      writeImage(bag, topics.depth, true, i, t, t);
      sensor_msgs::Image colour =
          imageFromColour(cv::Mat(120, 160, CV_8UC3, cv::Scalar::all(10)), "rgb8");
      colour.encoding = "jpeg";  // what a compressed stream republished wrongly might say
      colour.header.stamp.fromNSec(static_cast<std::uint64_t>(t));
      bag.write(topics.colour, colour.header.stamp, colour);
    }
    bag.close();
  }
  auto source = openBagSource(path);
  const Played played = playAll(*source);
  EXPECT_TRUE(played.frames.empty());
  EXPECT_LE(played.bad.size(), 1u) << "one error, not one per frame";
  EXPECT_NE(played.end_problem.find("'jpeg'"), std::string::npos) << played.end_problem;
  EXPECT_NE(played.end_problem.find(topics.colour), std::string::npos) << played.end_problem;
}

TEST(Ros1Bag, WhatIsNotABagIsNamed) {
  const fs::path dir = test::freshTempDir();
  std::ofstream(dir / "notes.bag") << "not a bag at all\n";
  const std::string message = messageOf([&] { openBagSource(dir / "notes.bag"); });
  EXPECT_NE(message.find("notes.bag"), std::string::npos) << message;
  EXPECT_NE(message.find("not a ROS 1 bag"), std::string::npos) << message;
  EXPECT_NE(messageOf([&] { openBagSource(dir / "missing.bag"); }).find("no such file"),
            std::string::npos);
}

TEST(Ros1Bag, ACutOffBagPlaysItsWholeFramesAndSaysWhere) {
  const fs::path dir = test::freshTempDir();
  const auto frames = randomFrames(30);
  writeBag(dir / "whole.bag", frames);
  const auto size = fs::file_size(dir / "whole.bag");
  {
    std::ifstream in(dir / "whole.bag", std::ios::binary);
    std::vector<char> bytes(size * 6 / 10);
    in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    std::ofstream(dir / "cut.bag", std::ios::binary)
        .write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  }
  auto source = openBagSource(dir / "cut.bag");
  const Played played = playAll(*source);
  EXPECT_GE(played.frames.size(), 12u);
  EXPECT_LT(played.frames.size(), 20u);
  expectSameFrames(played.frames, frames, 1e-9, true);
  EXPECT_NE(played.end_problem.find("cut.bag"), std::string::npos) << played.end_problem;
  EXPECT_NE(played.end_problem.find("salvaged"), std::string::npos) << played.end_problem;
}

TEST(Ros1Bag, ABagWhoseRecorderWasKilledIsSalvaged) {
  const fs::path path = test::freshTempDir() / "killed.bag";
  const auto frames = randomFrames(30);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    BagWriter writer(path);
    for (const core::Frame& frame : frames) writer.write(frame);
    std::_Exit(0);  // no close(), no destructor: the index is never written
  }
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  auto source = openBagSource(path);
  const Played played = playAll(*source);
  EXPECT_GE(played.frames.size(), 15u);
  expectSameFrames(played.frames, frames, 1e-9, true);
  EXPECT_NE(played.end_problem.find("index was never written"), std::string::npos)
      << played.end_problem;
}

TEST(Ros1Bag, TheTumFolderAndItsBagGiveTheSameFrames) {
  TESSERA_REQUIRE_SHARED("rgbd/tum_fr1_rpy_40");
  const fs::path folder = test::sharedData() / "rgbd/tum_fr1_rpy_40";
  const fs::path bag = test::freshTempDir() / "tum.bag";
  std::vector<core::Frame> frames;
  {
    DatasetSource source(folder);
    for (core::ReadResult r = source.read(); r.status != core::ReadStatus::kEndOfData;
         r = source.read()) {
      if (r.status == core::ReadStatus::kFrame) frames.push_back(std::move(r.frame));
    }
  }
  ASSERT_EQ(frames.size(), 40u);
  BagWriterOptions options;
  options.topics = tumTopics();
  options.depth_encoding = "32FC1";  // as TUM's own bags
  writeBag(bag, frames, options);
  auto source = openBagSource(bag);  // finds the tum topic set by itself
  const Played played = playAll(*source);
  ASSERT_EQ(played.frames.size(), 40u);
  expectSameFrames(played.frames, frames, 1e-6);
  EXPECT_DOUBLE_EQ(played.frames[0].intrinsics.fx, frames[0].intrinsics.fx);
}

}  // namespace
}  // namespace tessera::drivers::ros1
