// The live OpenNI2 path end to end, without hardware: the test driver in this folder presents
// a synthetic scene as an OpenNI2 device. Each test is its own ctest entry (tests/openni2_device/
// CMakeLists.txt) because the driver reads its settings when OpenNI2 starts, once per process.
#include <cmath>
#include <fstream>
#include <thread>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "support/test_data.h"
#include "tessera/core/error.h"
#include "tessera/core/registration.h"
#include "tessera/drivers/oni/oni_source.h"
#include "tessera/drivers/openni2/device_list.h"
#include "tessera/drivers/openni2/openni2_source.h"
#include "tessera/drivers/synthetic/renderer.h"
#include "tessera/drivers/v4l2/camera_calibration.h"
#include "tessera/pipeline/run.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;
using drivers::openni2::OpenNi2Options;
using drivers::openni2::OpenNi2Source;

constexpr const char* kDeviceUri = "tessera-test://office";

void requireTestDevice() {
  if (std::getenv("TESSERA_TEST_DEVICE_SCENE") == nullptr) {
    GTEST_SKIP() << "TESSERA_TEST_DEVICE_SCENE is not set: run this through ctest, which loads "
                    "the test OpenNI2 driver from its private folder";
  }
}

int envInt(const char* name) { return std::atoi(std::getenv(name)); }

struct MapPatch {
  Eigen::Vector3d normal;
  double offset_m = 0.0;
  double area_m2 = 0.0;
};

std::vector<MapPatch> readPatches(const fs::path& out_dir) {
  std::ifstream in(out_dir / "patches.json");
  const auto json = nlohmann::json::parse(in);
  std::vector<MapPatch> patches;
  for (const auto& p : json["patches"]) {
    const auto n = p["normal"].get<std::vector<double>>();
    patches.push_back(
        {{n[0], n[1], n[2]}, p["offset_m"].get<double>(), p["area_m2"].get<double>()});
  }
  return patches;
}

pipeline::RunSummary runInto(core::FrameSource& source, const fs::path& out_dir) {
  pipeline::RunOptions options;
  options.out_dir = out_dir;
  return pipeline::runPipeline(source, pipeline::loadRunConfig(std::nullopt), options);
}

TEST(OpenNi2Arguments, VideoModesAndUrisParseOrNameWhatIsWrong) {
  const auto mode = drivers::openni2::parseVideoMode("1280x1024@15");
  EXPECT_EQ(mode.width, 1280);
  EXPECT_EQ(mode.height, 1024);
  EXPECT_EQ(mode.fps, 15);
  for (const char* bad : {"640x480", "640x480@", "640*480@30", "640x480@30fps", "-640x480@30",
                          "640x0@30", " 640x480@30", "x480@30", ""}) {
    EXPECT_THROW(drivers::openni2::parseVideoMode(bad), core::ConfigError) << bad;
  }
  EXPECT_EQ(drivers::openni2::parseOpenNi2Uri("openni2://"), std::optional<std::string>(""));
  EXPECT_EQ(drivers::openni2::parseOpenNi2Uri("openni2://1d27/0601@2/5"),
            std::optional<std::string>("1d27/0601@2/5"));
  EXPECT_FALSE(drivers::openni2::parseOpenNi2Uri("recording.oni"));
}

TEST(LiveOpenNi2, ListsTheDeviceWithItsModes) {
  requireTestDevice();
  const auto devices = drivers::openni2::listDevices();
  const auto it = std::find_if(devices.begin(), devices.end(),
                               [](const auto& d) { return d.uri == kDeviceUri; });
  ASSERT_NE(it, devices.end());
  EXPECT_TRUE(it->problem.empty()) << it->problem;
  EXPECT_TRUE(it->hardware_registration);
  ASSERT_EQ(it->modes.size(), 2u);
  EXPECT_EQ(it->modes[0].sensor, "depth");
  EXPECT_EQ(it->modes[0].pixel_format, "depth 1 mm");
  EXPECT_EQ(it->modes[0].width, 640);
  EXPECT_EQ(it->modes[1].sensor, "colour");
  EXPECT_EQ(it->modes[1].pixel_format, "RGB888");
}

TEST(LiveOpenNi2, AModeTheDeviceDoesNotOfferIsAnErrorListingItsModes) {
  requireTestDevice();
  OpenNi2Options options;
  options.depth_mode = {320, 240, 60};
  try {
    OpenNi2Source source(options);
    FAIL() << "expected an error";
  } catch (const core::SourceError& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("320x240@60 is not offered"), std::string::npos) << message;
    EXPECT_NE(message.find("640x480@30 depth 1 mm"), std::string::npos) << message;
  }
  options = {};
  options.uri = "no-such-device://0";
  EXPECT_THROW(OpenNi2Source{options}, core::SourceError);
}

// Frames arrive unmirrored, registered and paired with the colour of their own timestamp: the
// first frame is exactly the scene's first view.
TEST(LiveOpenNi2, FramesAreTheScenesViewsUnmirroredAndPaired) {
  requireTestDevice();
  OpenNi2Source source(OpenNi2Options{});
  EXPECT_TRUE(source.hardwareRegistration());
  const core::ReadResult first = source.read();
  ASSERT_EQ(first.status, core::ReadStatus::kFrame) << first.problem;

  const auto scene = drivers::synthetic::loadScene(std::getenv("TESSERA_TEST_DEVICE_SCENE"));
  drivers::synthetic::CleanView view =
      drivers::synthetic::renderClean(scene, scene.sensor.intrinsics, scene.cameraPose(0), 1);
  cv::Mat depth_mm, rgb;
  drivers::synthetic::applySensor(scene.sensor, view, scene.seed * 1'000'003ULL, depth_mm, rgb);
  EXPECT_EQ(first.frame.timestamp_ns, scene.timestampNs(0));
  EXPECT_GT(first.frame.arrival_ns, 0);
  EXPECT_EQ(cv::norm(first.frame.depth_mm, depth_mm, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(first.frame.rgb, rgb, cv::NORM_INF), 0.0);
  // Field-of-view intrinsics: the focal length round-trips to within a thousandth of a pixel.
  EXPECT_NEAR(first.frame.intrinsics.fx, scene.sensor.intrinsics.fx, 1e-3);
}

// A device that cannot register colour (the scene's colour camera sits 2.5 cm beside the depth
// camera): with the calibration, frames carry the colour camera and registering them brings
// the colour much closer to the truth, the colour seen from the depth camera.
TEST(LiveOpenNi2, WithoutHardwareRegistrationTheCalibrationRegistersColour) {
  requireTestDevice();
  const fs::path dir = test::freshTempDir();
  const core::Intrinsics k = drivers::synthetic::SensorProfile::named("kinect_v1").intrinsics;
  const std::string intrinsics =
      fmt::format("{{width: {}, height: {}, fx: {}, fy: {}, cx: {}, cy: {}}}", k.width, k.height,
                  k.fx, k.fy, k.cx, k.cy);
  std::ofstream(dir / "calibration.yaml")
      << "mirror: false\ndepth: " << intrinsics << "\ncolour: " << intrinsics
      << "\nT_RGB_D: {rotation: [1, 0, 0, 0, 1, 0, 0, 0, 1], translation_m: [-0.025, 0, 0]}\n";
  const auto calibration = drivers::v4l2::loadCameraCalibration(dir / "calibration.yaml");
  OpenNi2Options options;
  options.colour_camera = calibration.colour;
  OpenNi2Source source(options);
  EXPECT_FALSE(source.hardwareRegistration());
  const core::ReadResult first = source.read();
  ASSERT_EQ(first.status, core::ReadStatus::kFrame) << first.problem;
  ASSERT_TRUE(first.frame.colour_camera);

  auto scene = drivers::synthetic::loadScene(std::getenv("TESSERA_TEST_DEVICE_SCENE"));
  const cv::Mat truth = drivers::synthetic::renderClean(scene, k, scene.cameraPose(0), 1).colour;
  const cv::Mat registered = core::registerColourToDepth(first.frame);
  cv::Mat valid = first.frame.depth_mm > 0;
  const auto meanError = [&](const cv::Mat& rgb) {
    cv::Mat rgb_f, diff;
    rgb.convertTo(rgb_f, CV_32FC3);
    cv::absdiff(rgb_f, truth, diff);
    const cv::Scalar mean = cv::mean(diff, valid);
    return (mean[0] + mean[1] + mean[2]) / 3.0;
  };
  const double raw_error = meanError(first.frame.rgb), registered_error = meanError(registered);
  EXPECT_LT(registered_error, 0.6 * raw_error)
      << "registered " << registered_error << ", as delivered " << raw_error;
}

// The device sends faster than this pipeline runs: what it cannot take is dropped and counted,
// never queued, so the latency stays bounded.
TEST(LiveOpenNi2, ABusyPipelineDropsFramesAndCountsThem) {
  requireTestDevice();
  OpenNi2Options options;
  options.reconnect_timeout_s = 0.0;
  OpenNi2Source source(options);
  const fs::path out = test::freshTempDir();
  const pipeline::RunSummary summary = runInto(source, out);
  const int sent = envInt("TESSERA_TEST_DEVICE_FRAMES");
  EXPECT_TRUE(summary.input.live);
  EXPECT_EQ(summary.input.live_stats.frames_delivered, static_cast<std::size_t>(sent));
  EXPECT_GT(summary.input.live_stats.frames_dropped, 0u);
  // Every frame sent is either fused, unreadable, or dropped: none is lost silently.
  EXPECT_EQ(
      summary.stream.frames + summary.input.frames_bad + summary.input.live_stats.frames_dropped,
      static_cast<std::size_t>(sent));
  ASSERT_TRUE(summary.stream.latency_ms_p50 && summary.stream.latency_ms_p95);
  EXPECT_GT(*summary.stream.latency_ms_p50, 0.0);
  EXPECT_GE(*summary.stream.latency_ms_p95, *summary.stream.latency_ms_p50);
  std::ifstream in(out / "report.json");
  const auto report = nlohmann::json::parse(in);
  EXPECT_EQ(report["frames_dropped"].get<std::size_t>(), summary.input.live_stats.frames_dropped);
  EXPECT_GT(report["drop_rate"].get<double>(), 0.0);
  EXPECT_FALSE(report["latency_ms_p95"].is_null());
  // The device left for good at its last frame: the run ended cleanly with the map exported.
  EXPECT_NE(summary.input.end_problem.find("did not come back"), std::string::npos);
  EXPECT_TRUE(fs::exists(out / "patches.obj"));
}

// A run stopped early (--max-frames, as Ctrl-C does) stops the device: the counts are final,
// with the frames still queued counted as dropped, and the recording ends there too.
TEST(LiveOpenNi2, StoppingEarlyStopsTheDeviceAndItsRecording) {
  requireTestDevice();
  const fs::path dir = test::freshTempDir();
  OpenNi2Options options;
  options.record_path = dir / "live.oni";
  pipeline::RunSummary summary;
  {
    OpenNi2Source source(options);
    pipeline::RunOptions run;
    run.out_dir = dir / "out";
    run.max_frames = 5;
    summary = pipeline::runPipeline(source, pipeline::loadRunConfig(std::nullopt), run);
    std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the device would go on
    EXPECT_EQ(source.liveStats().frames_delivered, summary.input.live_stats.frames_delivered);
  }
  EXPECT_EQ(summary.stream.frames, 5u);
  EXPECT_EQ(
      summary.stream.frames + summary.input.frames_bad + summary.input.live_stats.frames_dropped,
      summary.input.live_stats.frames_delivered);
  drivers::oni::OniSource recording(dir / "live.oni");
  ASSERT_TRUE(recording.frameCount());
  EXPECT_GE(*recording.frameCount() + 1, summary.input.live_stats.frames_delivered);
  EXPECT_LE(*recording.frameCount(), summary.input.live_stats.frames_delivered);
}

// A run that records the device through OpenNI2's Recorder: replaying the recording builds the
// same map as the live run (the device is slow enough that nothing is dropped).
TEST(LiveOpenNi2, ARecordingMadeLiveReplaysToTheSameMap) {
  requireTestDevice();
  const fs::path dir = test::freshTempDir();
  OpenNi2Options options;
  options.reconnect_timeout_s = 0.0;
  options.record_path = dir / "live.oni";
  pipeline::RunSummary live;
  {
    OpenNi2Source source(options);
    live = runInto(source, dir / "live");
  }
  const int sent = envInt("TESSERA_TEST_DEVICE_FRAMES");
  ASSERT_EQ(live.input.live_stats.frames_delivered, static_cast<std::size_t>(sent));
  // OpenNI2's Recorder starts on its own thread and may miss the first frame of a heavily
  // loaded run (the source waits 200 ms for it); it records every later frame.
  drivers::oni::OniSource recording(dir / "live.oni");
  ASSERT_TRUE(recording.frameCount());
  EXPECT_GE(*recording.frameCount() + 1, static_cast<std::size_t>(sent));
  EXPECT_LE(*recording.frameCount(), static_cast<std::size_t>(sent));
  EXPECT_NEAR(recording.intrinsics().fx, 525.0, 1e-3);  // from the sidecar the run wrote
  const pipeline::RunSummary replay = runInto(recording, dir / "replay");
  EXPECT_EQ(replay.stream.frames, *recording.frameCount());

  // The same planes: every live patch has a replayed twin within 2 degrees and 3 cm, with an
  // area within 15 %, and the meshes differ by under 5 % (apart from dropped frames, the two
  // runs saw the same images).
  const auto live_patches = readPatches(dir / "live");
  const auto replay_patches = readPatches(dir / "replay");
  ASSERT_GE(live_patches.size(), 3u);
  EXPECT_EQ(live_patches.size(), replay_patches.size());
  for (const MapPatch& p : live_patches) {
    const bool twin = std::any_of(replay_patches.begin(), replay_patches.end(), [&](const auto& q) {
      return std::acos(std::clamp(p.normal.dot(q.normal), -1.0, 1.0)) < 2.0 * M_PI / 180.0 &&
             std::abs(p.offset_m - q.offset_m) < 0.03 &&
             std::abs(p.area_m2 - q.area_m2) < 0.15 * std::max(p.area_m2, q.area_m2);
    });
    EXPECT_TRUE(twin) << "live patch with normal " << p.normal.transpose() << ", offset "
                      << p.offset_m << " m, area " << p.area_m2 << " m2 has no replayed twin";
  }
  const double vertices_ratio = static_cast<double>(live.exported.mesh_vertices) /
                                static_cast<double>(replay.exported.mesh_vertices);
  EXPECT_NEAR(vertices_ratio, 1.0, 0.05);
}

// Unplugged in the middle: the run finalizes what it has, waits, resumes when the device is
// back, and the recording continues in a second segment.
TEST(LiveOpenNi2, AnUnpluggedDeviceIsWaitedForAndResumes) {
  requireTestDevice();
  const fs::path dir = test::freshTempDir();
  OpenNi2Options options;
  options.reconnect_timeout_s = 3.0;
  options.record_path = dir / "live.oni";
  pipeline::RunSummary summary;
  {
    OpenNi2Source source(options);
    summary = runInto(source, dir / "out");
  }
  const int frames = envInt("TESSERA_TEST_DEVICE_FRAMES");
  const int unplug_at = envInt("TESSERA_TEST_DEVICE_UNPLUG_AT");
  // The frames the scene moved on by while the device was away (at its delivery rate).
  const int away = static_cast<int>(std::lround(envInt("TESSERA_TEST_DEVICE_REPLUG_MS") *
                                                envInt("TESSERA_TEST_DEVICE_FPS") / 1000.0));
  EXPECT_EQ(summary.input.live_stats.device_losses, 2u);  // the unplug, then the end of the scene
  EXPECT_EQ(summary.input.live_stats.reconnects, 1u);
  EXPECT_EQ(summary.stream.interruptions, 2u);
  EXPECT_EQ(summary.input.live_stats.frames_delivered, static_cast<std::size_t>(frames - away));
  EXPECT_EQ(
      summary.stream.frames + summary.input.frames_bad + summary.input.live_stats.frames_dropped,
      static_cast<std::size_t>(frames - away));
  EXPECT_GT(summary.patches.patches_finalized, 0u);

  // The interruption is in stats.jsonl, with the patches it finalized.
  std::ifstream stats(dir / "out" / "stats.jsonl");
  std::string line;
  bool interrupted = false, finalized_then = false;
  std::int64_t last_timestamp_ns = -1;
  while (std::getline(stats, line)) {
    const auto json = nlohmann::json::parse(line);
    if (json["type"] == "frame") {  // in order across the reconnect
      EXPECT_GT(json["timestamp_ns"].get<std::int64_t>(), last_timestamp_ns);
      last_timestamp_ns = json["timestamp_ns"].get<std::int64_t>();
    }
    if (json["type"] == "source") interrupted = true;
    if (interrupted && json["type"] == "patch" && json["event"] == "finalized")
      finalized_then = true;
  }
  EXPECT_TRUE(interrupted);
  EXPECT_TRUE(finalized_then);

  // Two recording segments, each playable: before the unplug and after the replug (each may
  // miss its first frame, as above).
  drivers::oni::OniSource before(dir / "live.oni");
  drivers::oni::OniSource after(dir / "live-2.oni");
  ASSERT_TRUE(before.frameCount() && after.frameCount());
  EXPECT_GE(*before.frameCount() + 1, static_cast<std::size_t>(unplug_at));
  EXPECT_LE(*before.frameCount(), static_cast<std::size_t>(unplug_at));
  EXPECT_GE(*after.frameCount() + 1, static_cast<std::size_t>(frames - unplug_at - away));
  EXPECT_LE(*after.frameCount(), static_cast<std::size_t>(frames - unplug_at - away));
}

}  // namespace
}  // namespace tessera
