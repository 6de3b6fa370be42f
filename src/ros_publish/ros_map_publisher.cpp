#include "tessera/ros_publish/ros_map_publisher.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "internal/ros_bus.h"

namespace tessera::ros_publish {

namespace {

// The bitmap in square cells of `cell` texels, each drawn as two triangles in the mean colour
// of its texels inside the outline (cells less than half inside are left out).
internal::ColouredMesh meshOf(const pipeline::PatchSurface& patch, int max_quads) {
  const texture::TexelGrid& grid = *patch.grid;
  const cv::Mat& image = *patch.image;
  internal::ColouredMesh mesh;
  mesh.id = patch.id;
  const double inside = grid.mask.empty() ? 0.0 : cv::countNonZero(grid.mask);
  if (inside == 0.0) return mesh;
  const int cell = std::max(1, static_cast<int>(std::ceil(std::sqrt(inside / max_quads))));
  const auto corner = [&](int col, int row) {
    const Eigen::Vector2d uv = grid.uvOf(col, row);
    return patch.plane.at(uv.x(), uv.y()).cast<float>().eval();
  };
  for (int row = 0; row < grid.height; row += cell) {
    for (int col = 0; col < grid.width; col += cell) {
      const int rows = std::min(cell, grid.height - row), cols = std::min(cell, grid.width - col);
      cv::Vec3d sum(0, 0, 0);
      int count = 0;
      for (int y = row; y < row + rows; ++y) {
        for (int x = col; x < col + cols; ++x) {
          if (grid.mask.at<std::uint8_t>(y, x) == 0) continue;
          sum += cv::Vec3d(image.at<cv::Vec3b>(y, x));
          ++count;
        }
      }
      if (2 * count < rows * cols) continue;
      const std::array<float, 3> colour = {static_cast<float>(sum[0] / count / 255.0),
                                           static_cast<float>(sum[1] / count / 255.0),
                                           static_cast<float>(sum[2] / count / 255.0)};
      const Eigen::Vector3f a = corner(col, row), b = corner(col + cols, row),
                            c = corner(col + cols, row + rows), d = corner(col, row + rows);
      for (const Eigen::Vector3f& v : {a, b, c, a, c, d}) {
        mesh.vertices.push_back(v);
        mesh.colours.push_back(colour);
      }
    }
  }
  return mesh;
}

// The monitor's /stats figures as diagnostics key-values (nested ones flattened, a.b).
void flatten(const nlohmann::json& json, const std::string& prefix,
             std::vector<std::pair<std::string, std::string>>& out) {
  for (const auto& [key, value] : json.items()) {
    if (key == "report") continue;  // the whole report.json: too much for a status line
    const std::string name = prefix.empty() ? key : prefix + "." + key;
    if (value.is_object()) {
      flatten(value, name, out);
    } else if (value.is_string()) {
      out.emplace_back(name, value.get<std::string>());
    } else if (value.is_number_float()) {
      out.emplace_back(name, fmt::format("{:.4g}", value.get<double>()));
    } else {
      out.emplace_back(name, value.dump());
    }
  }
}

}  // namespace

RosMapPublisher::RosMapPublisher(const RosPublisherOptions& options,
                                 const pipeline::MapMonitor& monitor, std::string source_name)
    : options_(options),
      monitor_(monitor),
      source_name_(std::move(source_name)),
      bus_(std::make_unique<internal::RosBus>(options.master_uri, options.map_frame,
                                              options.camera_frame)),
      figures_thread_([this] { figuresLoop(); }) {}

RosMapPublisher::~RosMapPublisher() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  figures_thread_.join();
}

void RosMapPublisher::onPose(std::int64_t timestamp_ns, const core::Isometry& T_W_C) {
  bus_->publishPose(options_.stamp_with_frame_time ? timestamp_ns : 0, T_W_C);
}

void RosMapPublisher::onPatch(const pipeline::PatchSurface& patch) {
  if (patch.grid == nullptr || patch.image == nullptr) return;
  bus_->publishPatch(meshOf(patch, options_.max_quads_per_patch));
}

void RosMapPublisher::onPatchRetired(int patch_id) { bus_->deletePatch(patch_id); }

void RosMapPublisher::onExported(const std::vector<std::filesystem::path>& files) {
  publishFigures();
  std::vector<std::string> paths;
  for (const auto& file : files) paths.push_back(file.string());
  bus_->publishFiles(paths);
}

void RosMapPublisher::publishFigures() {
  const pipeline::MonitorSnapshot snapshot = monitor_.snapshot();
  const nlohmann::json figures = pipeline::toJson(snapshot);
  std::vector<std::pair<std::string, std::string>> values;
  flatten(figures, "", values);
  const std::size_t dropped = snapshot.frame.frames_dropped;
  const std::size_t seen = snapshot.frame.frames_done + dropped;
  const double drop_rate =
      seen == 0 ? 0.0 : static_cast<double>(dropped) / static_cast<double>(seen);
  const internal::Level level = drop_rate > 0.1 ? internal::Level::kWarn : internal::Level::kOk;
  const std::string message = fmt::format(
      "{}: {} frames, {:.1f} MB map, {} patches{}", snapshot.state, snapshot.frame.frames_done,
      static_cast<double>(snapshot.frame.map_bytes) / 1e6, snapshot.patches_committed,
      drop_rate > 0.1 ? fmt::format(", {:.0f} % of frames dropped", 100 * drop_rate) : "");
  bus_->publishFigures("tessera: map", source_name_, level, message, values, figures.dump());
}

void RosMapPublisher::figuresLoop() {
  const auto period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(options_.figures_period_s));
  std::unique_lock lock(mutex_);
  while (!wake_.wait_for(lock, period, [this] { return stopping_; })) {
    lock.unlock();
    try {
      publishFigures();
    } catch (const std::exception& e) {  // a figure that cannot be formatted: say so, go on
      spdlog::warn("ROS figures: {}", e.what());
    }
    lock.lock();
  }
}

}  // namespace tessera::ros_publish
