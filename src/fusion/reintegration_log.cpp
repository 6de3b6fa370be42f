#include "tessera/fusion/reintegration_log.h"

#include <chrono>
#include <system_error>
#include <utility>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"

namespace tessera::fusion {

namespace {

// Every scale-th depth reading, as TsdfMap::integrate takes them.
cv::Mat subsampledDepth(const cv::Mat& depth_mm, int scale) {
  cv::Mat out(depth_mm.rows / scale, depth_mm.cols / scale, CV_16UC1);
  for (int v = 0; v < out.rows; ++v) {
    const auto* src = depth_mm.ptr<std::uint16_t>(v * scale);
    auto* dst = out.ptr<std::uint16_t>(v);
    for (int u = 0; u < out.cols; ++u) dst[u] = src[u * scale];
  }
  return out;
}

// JPEG at this quality: the TSDF's vertex colours average many views, and a 320 x 240 frame
// takes about 30 KB instead of 150 KB as PNG.
constexpr int kColourJpegQuality = 95;

// A long run's correction says how far it is every this many frames (about 15 s).
constexpr std::size_t kProgressEvery = 1000;

}  // namespace

ReintegrationLog::ReintegrationLog(std::filesystem::path dir, int scale)
    : dir_(std::move(dir)), scale_(std::max(1, scale)) {
  std::error_code error;
  std::filesystem::create_directories(dir_, error);
  if (error) {
    error_ = fmt::format("{}: cannot create the folder: {}", dir_.string(), error.message());
    spdlog::warn("TSDF correction off: {}", error_);
  }
}

ReintegrationLog::~ReintegrationLog() {
  std::error_code ignored;
  std::filesystem::remove_all(dir_, ignored);
}

void ReintegrationLog::keep(const core::Frame& frame, const core::Isometry& T_W_C,
                            std::int64_t anchor_ns) {
  if (!usable() || frame.depth_mm.empty()) return;
  Entry entry;
  entry.anchor_ns = anchor_ns;
  entry.T_W_C = T_W_C;
  const cv::Mat depth = subsampledDepth(frame.depth_mm, scale_);
  cv::Mat colour(depth.size(), CV_8UC3, cv::Scalar(128, 128, 128));  // BGR for imwrite
  if (!frame.rgb.empty()) {
    cv::Mat sized;
    cv::resize(frame.rgb, sized, depth.size(), 0, 0, cv::INTER_AREA);
    cv::cvtColor(sized, colour, cv::COLOR_RGB2BGR);
  }
  const core::Intrinsics& k = frame.intrinsics;
  // Pixel u of the subsampled image is pixel scale*u of the original.
  entry.intrinsics = k;
  entry.intrinsics.width = depth.cols;
  entry.intrinsics.height = depth.rows;
  entry.intrinsics.fx = k.fx / scale_;
  entry.intrinsics.fy = k.fy / scale_;
  entry.intrinsics.cx = k.cx / scale_;
  entry.intrinsics.cy = k.cy / scale_;
  const std::string stem = fmt::format("{:06}", entries_.size());
  entry.depth = dir_ / (stem + "_depth.png");
  entry.colour = dir_ / (stem + "_colour.jpg");
  bool written = false;
  try {
    written =
        cv::imwrite(entry.depth.string(), depth) &&
        cv::imwrite(entry.colour.string(), colour, {cv::IMWRITE_JPEG_QUALITY, kColourJpegQuality});
  } catch (const cv::Exception& e) {
    spdlog::debug("{}: {}", entry.depth.string(), e.what());
  }
  if (!written) {
    error_ =
        fmt::format("{}: cannot write frame {} (is the disk full?)", dir_.string(), frame.index);
    spdlog::warn("TSDF correction off: {}; the mesh stays at the tracked poses", error_);
    return;
  }
  std::error_code ignored;
  disk_bytes_ += std::filesystem::file_size(entry.depth, ignored) +
                 std::filesystem::file_size(entry.colour, ignored);
  entries_.push_back(std::move(entry));
}

SurfaceMesh ReintegrationLog::rebuild(
    const TsdfConfig& config,
    const std::function<std::optional<core::Isometry>(std::int64_t)>& correction) const {
  if (!usable()) throw core::Error(error_);
  TsdfConfig stored = config;
  stored.integration_scale = 1;  // the frames were kept at the integration resolution
  TsdfMap map(stored);
  std::uint64_t index = 0;
  using Clock = std::chrono::steady_clock;
  const auto seconds = [](Clock::duration d) { return std::chrono::duration<double>(d).count(); };
  Clock::duration reading{}, fusing{};
  for (const Entry& entry : entries_) {
    const std::optional<core::Isometry> motion = correction(entry.anchor_ns);
    core::Frame frame;
    frame.index = index++;
    if (!motion) continue;
    const auto read_start = Clock::now();
    frame.intrinsics = entry.intrinsics;
    frame.depth_mm = cv::imread(entry.depth.string(), cv::IMREAD_UNCHANGED);
    const cv::Mat colour = cv::imread(entry.colour.string(), cv::IMREAD_COLOR);
    if (frame.depth_mm.type() != CV_16UC1 || colour.size() != frame.depth_mm.size()) {
      throw core::Error(fmt::format("{}: kept frame {} is unreadable", dir_.string(), frame.index));
    }
    cv::cvtColor(colour, frame.rgb, cv::COLOR_BGR2RGB);
    const auto fuse_start = Clock::now();
    reading += fuse_start - read_start;
    const core::Isometry T_W_C = *motion * entry.T_W_C;
    map.integrate(frame, T_W_C);
    if (config.release_distance_m > 0.0) map.releaseBlocksBehind(T_W_C, config.release_distance_m);
    fusing += Clock::now() - fuse_start;
    if (index % kProgressEvery == 0 && index < entries_.size()) {
      spdlog::info("TSDF correction: {} of {} keyframes fused again", index, entries_.size());
    }
  }
  const auto mesh_start = Clock::now();
  SurfaceMesh mesh = map.extractMesh();
  spdlog::debug(
      "TSDF correction: reading the kept frames {:.2f} s, fusing {:.2f} s, the mesh {:.2f} s",
      seconds(reading), seconds(fusing), seconds(Clock::now() - mesh_start));
  return mesh;
}

}  // namespace tessera::fusion
