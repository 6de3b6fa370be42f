// The freenect source against Debian's fakenect, which replays a dump folder in place of a
// Kinect v1. Each test writes its dump and points FAKENECT_PATH at it; fakenect reads that
// variable once per process, so ctest runs every test in its own process, with LD_LIBRARY_PATH
// at fakenect's folder (tests/CMakeLists.txt).
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <thread>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "tessera/core/error.h"
#include "tessera/drivers/freenect/freenect_source.h"
#include "tessera/drivers/freenect/kinect_v1.h"

namespace tessera::drivers::freenect {
namespace {

namespace fs = std::filesystem;
using core::ReadStatus;

constexpr int kWidth = 640, kHeight = 480;
constexpr std::uint32_t kTicksPerFrame = 2'000'000;  // 30 Hz on the 60 MHz device clock
// Starts three frames before the 32-bit device clock wraps around.
constexpr std::uint32_t kFirstStamp = 0xFFFFFFFFu - 3 * kTicksPerFrame + 1;
constexpr double kRightWallMm = 2000.0;

// The scene of frame k: a wall split down the middle, the left half 1000 + 100 k mm away, the
// right half at 2 m; the top 10 rows without depth. Colour: left (200, 40, 10 k), right
// (10, 120, 250).
double leftWallMm(int k) { return 1000.0 + 100.0 * k; }
cv::Vec3b leftColour(int k) { return {200, 40, static_cast<unsigned char>(10 * k)}; }
const cv::Vec3b kRightColour(10, 120, 250);

// The raw disparity of a wall z mm away: Burrus' model (kinect_v1.h) solved for the raw value.
std::uint16_t rawFor(double mm) {
  return static_cast<std::uint16_t>(std::lround((1000.0 / mm - 3.3309495161) / -0.0030711016));
}
// Half the spacing of the depths the model gives near z, plus rounding to whole millimetres.
double halfStepMm(double mm) { return 0.5 * mm * mm * 0.0030711016 / 1000.0 + 0.5; }

// Writes a dump as libfreenect's `record` does (the format is described in fakenect_dump.h).
class Dump {
 public:
  explicit Dump(const std::string& name)
      : folder_(fs::temp_directory_path() / fmt::format("tessera_fakenect_{}_{}", name, getpid())) {
    fs::remove_all(folder_);
    fs::create_directories(folder_);
  }
  ~Dump() { fs::remove_all(folder_); }

  // Frame k of the scene at 30 Hz; colour 1000 ticks (17 us) after its depth frame.
  void addFrame(int k, bool with_colour = true) {
    std::vector<std::uint16_t> raw(kWidth * kHeight);
    for (int y = 0; y < kHeight; ++y) {
      for (int x = 0; x < kWidth; ++x) {
        raw[static_cast<std::size_t>(y * kWidth + x)] =
            y < 10 ? kRawNoDepth : rawFor(x < kWidth / 2 ? leftWallMm(k) : kRightWallMm);
      }
    }
    std::string depth(reinterpret_cast<const char*>(raw.data()), raw.size() * 2);
    const std::uint32_t stamp = kFirstStamp + static_cast<std::uint32_t>(k) * kTicksPerFrame;
    add('d', k / 30.0, stamp, "P5 640 480 65535\n" + depth);
    if (!with_colour) return;
    std::string rgb;
    for (int y = 0; y < kHeight; ++y) {
      for (int x = 0; x < kWidth; ++x) {
        const cv::Vec3b c = x < kWidth / 2 ? leftColour(k) : kRightColour;
        rgb.append({static_cast<char>(c[0]), static_cast<char>(c[1]), static_cast<char>(c[2])});
      }
    }
    add('r', k / 30.0 + 0.001, stamp + 1000, "P6 640 480 255\n" + rgb);
  }

  // A file and its INDEX.txt line; returns the file's path.
  fs::path add(char type, double host_s, std::uint32_t stamp, const std::string& bytes) {
    const std::string name = fmt::format("{}-{:.6f}-{}-{}.p{}m", type, host_s, stamp, lines_.size(),
                                         type == 'd' ? 'g' : 'p');
    std::ofstream(folder_ / name, std::ios::binary) << bytes;
    lines_.push_back(name);
    std::ofstream index(folder_ / "INDEX.txt");
    for (const std::string& line : lines_) index << line << '\n';
    return folder_ / name;
  }

  const fs::path& folder() const { return folder_; }

 private:
  fs::path folder_;
  std::vector<std::string> lines_;
};

// A deep queue by default, so that a reader stalled by a loaded machine (ctest -j2, ASan)
// drops nothing and the exact counts hold; the drops test asks for the real depth of 2.
std::unique_ptr<core::FrameSource> replay(const Dump& dump, double reconnect_timeout_s = 0.3,
                                          const std::string& uri = "freenect://",
                                          std::size_t queue_frames = 64) {
  setenv("FAKENECT_PATH", dump.folder().c_str(), 1);
  FreenectOptions options;
  options.queue_frames = queue_frames;
  options.reconnect_timeout_s = reconnect_timeout_s;
  options.frame_timeout_ms = 1000;
  return openFreenectSource(uri, options);
}

class Freenect : public testing::Test {
 protected:
  void SetUp() override {
    const std::vector<std::string> devices = listFreenectDevices();
    ASSERT_EQ(devices.size(), 1u) << "run through ctest: these tests need fakenect loaded "
                                     "(LD_LIBRARY_PATH at Debian's fakenect folder)";
    ASSERT_NE(devices[0].find("fakenect replay"), std::string::npos) << devices[0];
  }
};

TEST_F(Freenect, FramesAreTheWallInMillimetresWithTheWrittenColours) {
  Dump dump("frames");
  for (int k = 0; k < 5; ++k) dump.addFrame(k);
  auto source = replay(dump);
  EXPECT_TRUE(source->isLive());
  EXPECT_EQ(source->name(), "freenect://0");
  int frames = 0;
  for (core::ReadResult r = source->read(); r.status == ReadStatus::kFrame; r = source->read()) {
    const int k = frames++;
    const core::Frame& f = r.frame;
    EXPECT_EQ(f.index, static_cast<std::uint64_t>(k));
    ASSERT_EQ(f.depth_mm.type(), CV_16UC1);
    ASSERT_EQ(f.rgb.type(), CV_8UC3);
    ASSERT_EQ(f.depth_mm.size(), cv::Size(kWidth, kHeight));
    // Each half holds one depth, near the wall's (within the disparity quantisation).
    const std::uint16_t left = f.depth_mm.at<std::uint16_t>(240, 100);
    const std::uint16_t right = f.depth_mm.at<std::uint16_t>(240, 500);
    EXPECT_NEAR(left, leftWallMm(k), halfStepMm(leftWallMm(k))) << "frame " << k;
    EXPECT_NEAR(right, kRightWallMm, halfStepMm(kRightWallMm)) << "frame " << k;
    const cv::Rect left_half(0, 10, kWidth / 2, kHeight - 10);
    const cv::Rect right_half(kWidth / 2, 10, kWidth / 2, kHeight - 10);
    EXPECT_EQ(cv::countNonZero(f.depth_mm(left_half) != left), 0);
    EXPECT_EQ(cv::countNonZero(f.depth_mm(right_half) != right), 0);
    EXPECT_EQ(cv::countNonZero(f.depth_mm(cv::Rect(0, 0, kWidth, 10))), 0) << "no depth: 0";
    // The colours as written, R, G, B, not mirrored, from the paired colour frame.
    EXPECT_EQ(f.rgb.at<cv::Vec3b>(240, 100), leftColour(k)) << "frame " << k;
    EXPECT_EQ(f.rgb.at<cv::Vec3b>(5, 600), kRightColour) << "frame " << k;
    // fakenect offers only raw disparity: depth is not registered to colour.
    EXPECT_NEAR(f.intrinsics.fx, 575.8, 0.1);
    EXPECT_EQ(f.intrinsics.width, kWidth);
    ASSERT_TRUE(f.colour_camera.has_value());
    EXPECT_EQ(f.colour_camera->intrinsics.fx, 525.0);
    EXPECT_NEAR(f.colour_camera->T_RGB_D.translation().norm(), 0.025, 1e-9);
  }
  EXPECT_EQ(frames, 5);
}

TEST_F(Freenect, TimestampsFollowTheDeviceClockAcrossItsWrapAround) {
  Dump dump("timestamps");
  for (int k = 0; k < 6; ++k) dump.addFrame(k);  // the clock wraps after frame 2
  auto source = replay(dump);
  std::vector<core::Frame> frames;
  for (core::ReadResult r = source->read(); r.status == ReadStatus::kFrame; r = source->read()) {
    frames.push_back(std::move(r.frame));
  }
  ASSERT_EQ(frames.size(), 6u);
  for (std::size_t i = 1; i < frames.size(); ++i) {
    // 2,000,000 ticks of 60 MHz: 33.3 ms.
    EXPECT_NEAR(static_cast<double>(frames[i].timestamp_ns - frames[i - 1].timestamp_ns),
                33'333'333.0, 1.0)
        << i;
    EXPECT_GT(frames[i].arrival_ns, frames[i - 1].arrival_ns) << i;
  }
  EXPECT_GT(frames[0].arrival_ns, 0);
}

TEST_F(Freenect, TheEndOfTheDumpInterruptsThenEndsTheStreamNamingTheDevice) {
  Dump dump("end");
  for (int k = 0; k < 3; ++k) dump.addFrame(k);
  auto source = replay(dump, 0.5);
  for (int k = 0; k < 3; ++k) ASSERT_EQ(source->read().status, ReadStatus::kFrame) << k;
  const core::ReadResult lost = source->read();
  EXPECT_EQ(lost.status, ReadStatus::kInterrupted);
  EXPECT_NE(lost.problem.find("freenect://0"), std::string::npos) << lost.problem;
  EXPECT_NE(lost.problem.find("no more frames"), std::string::npos) << lost.problem;
  const auto start = std::chrono::steady_clock::now();
  const core::ReadResult end = source->read();
  const double waited_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_EQ(end.status, ReadStatus::kEndOfData);
  EXPECT_NE(end.problem.find("freenect://0"), std::string::npos) << end.problem;
  EXPECT_NE(end.problem.find("did not come back within 0.5 s"), std::string::npos) << end.problem;
  EXPECT_GE(waited_s, 0.45);  // reconnect attempts for reconnect_timeout_s
  EXPECT_LT(waited_s, 2.0);
  EXPECT_EQ(source->read().status, ReadStatus::kEndOfData);
  const core::LiveStats stats = source->liveStats();
  EXPECT_EQ(stats.frames_delivered, 3u);
  EXPECT_EQ(stats.frames_dropped, 0u);
  EXPECT_EQ(stats.device_losses, 1u);
  EXPECT_EQ(stats.reconnects, 0u);
}

TEST_F(Freenect, ABusyReaderGetsTheNewestFramesAndTheDropsAreCounted) {
  Dump dump("drops");
  for (int k = 0; k < 8; ++k) dump.addFrame(k);
  auto source = replay(dump, 0.3, "freenect://", 2);
  // Read nothing until fakenect has replayed the whole dump (8 frames at 30 Hz).
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(3);
  while (source->liveStats().frames_delivered < 8 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(50));  // the last colour frame
  for (int k : {6, 7}) {
    const core::ReadResult r = source->read();
    ASSERT_EQ(r.status, ReadStatus::kFrame) << r.problem;
    EXPECT_NEAR(r.frame.depth_mm.at<std::uint16_t>(240, 100), leftWallMm(k),
                halfStepMm(leftWallMm(k)));
    EXPECT_EQ(r.frame.rgb.at<cv::Vec3b>(240, 100), leftColour(k));
  }
  EXPECT_EQ(source->read().status, ReadStatus::kInterrupted);
  const core::LiveStats stats = source->liveStats();
  EXPECT_EQ(stats.frames_delivered, 8u);
  EXPECT_EQ(stats.frames_dropped, 6u);
}

TEST_F(Freenect, ADepthFrameWithoutColourIsABadFrameAndTheStreamGoesOn) {
  Dump dump("unpaired");
  dump.addFrame(0);
  dump.addFrame(1, /*with_colour=*/false);
  dump.addFrame(2);
  auto source = replay(dump);
  EXPECT_EQ(source->read().status, ReadStatus::kFrame);
  const core::ReadResult bad = source->read();
  EXPECT_EQ(bad.status, ReadStatus::kBadFrame);
  EXPECT_NE(bad.problem.find("no colour frame within"), std::string::npos) << bad.problem;
  const core::ReadResult next = source->read();
  ASSERT_EQ(next.status, ReadStatus::kFrame) << next.problem;
  EXPECT_EQ(next.frame.rgb.at<cv::Vec3b>(240, 100), leftColour(2));
  EXPECT_EQ(next.frame.index, 1u);
}

// fakenect itself would end the process (missing file) or read past a short one: the source
// checks the dump first and refuses it with the file's name.
TEST_F(Freenect, ATruncatedOrMissingDumpFileIsAClearError) {
  const auto expectError = [](const Dump& dump, const std::string& part1,
                              const std::string& part2) {
    try {
      replay(dump);
      ADD_FAILURE() << "no error for a dump with " << part2;
    } catch (const core::SourceError& e) {
      EXPECT_NE(std::string(e.what()).find(part1), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(part2), std::string::npos) << e.what();
    }
  };
  Dump truncated("truncated");
  truncated.addFrame(0);
  const fs::path cut = truncated.add('d', 0.04, 5, "P5 640 480 65535\n" + std::string(1000, 'x'));
  expectError(truncated, cut.filename().string(), "truncated");
  Dump headless("headless");
  const fs::path bad = headless.add('r', 0.0, 5, std::string(kWidth * kHeight * 3 + 20, 'x'));
  expectError(headless, bad.filename().string(), "no header line");
  Dump missing("missing");
  const fs::path gone = missing.add('a', 0.0, 5, "");
  fs::remove(gone);
  expectError(missing, gone.filename().string(), "missing");
}

TEST_F(Freenect, UrisSelectADeviceAndBadOnesAreClearErrors) {
  EXPECT_EQ(parseFreenectUri("freenect://"), 0);
  EXPECT_EQ(parseFreenectUri("freenect://2"), 2);
  EXPECT_EQ(parseFreenectUri("openni2://"), std::nullopt);
  EXPECT_THROW(parseFreenectUri("freenect://first"), core::ConfigError);
  EXPECT_THROW(openFreenectSource("v4l2:///dev/video0", {}), core::ConfigError);
  Dump dump("uris");
  dump.addFrame(0);
  try {
    replay(dump, 0.3, "freenect://1");
    ADD_FAILURE() << "freenect://1 opened with one device";
  } catch (const core::SourceError& e) {
    EXPECT_NE(std::string(e.what()).find("freenect://1"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("finds 1"), std::string::npos) << e.what();
  }
  unsetenv("FAKENECT_PATH");
  try {
    openFreenectSource("freenect://", {});
    ADD_FAILURE() << "opened without FAKENECT_PATH";
  } catch (const core::SourceError& e) {
    EXPECT_NE(std::string(e.what()).find("FAKENECT_PATH"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tessera::drivers::freenect
