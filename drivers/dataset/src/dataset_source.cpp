#include "tessera/drivers/dataset_source.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "internal/layouts.h"
#include "tessera/core/error.h"

namespace tessera::drivers {

namespace fs = std::filesystem;

std::string layoutName(DatasetLayout layout) {
  switch (layout) {
    case DatasetLayout::kTum:
      return "TUM RGB-D";
    case DatasetLayout::kSevenScenes:
      return "7-Scenes";
    case DatasetLayout::kRedwood:
      return "Redwood";
    case DatasetLayout::kSlambook:
      return "slambook";
  }
  return "unknown";
}

DatasetLayout detectDatasetLayout(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    throw core::SourceError(fmt::format("{}: no such folder", dir.string()));
  }
  if (fs::exists(dir / "rgb.txt") && fs::exists(dir / "depth.txt")) return DatasetLayout::kTum;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("frame-", 0) == 0 && name.find(".color.") != std::string::npos) {
      return DatasetLayout::kSevenScenes;
    }
  }
  if (fs::is_directory(dir / "color") && fs::is_directory(dir / "depth")) {
    return fs::exists(dir / "pose.txt") ? DatasetLayout::kSlambook : DatasetLayout::kRedwood;
  }
  throw core::SourceError(fmt::format(
      "{}: not a recording tessera knows. Known folder layouts:\n"
      "  TUM RGB-D  rgb.txt + depth.txt (+ associations.txt, groundtruth.txt)\n"
      "  7-Scenes   frame-N.color.png|jpg / .depth.png / .pose.txt (+ camera-intrinsics.txt)\n"
      "  Redwood    color/ + depth/ (+ rgbd.match, trajectory.log, intrinsic JSON)\n"
      "  slambook   color/ + depth/ + pose.txt",
      dir.string()));
}

DatasetSource::DatasetSource(const fs::path& dir, const DatasetOptions& options)
    : dir_(dir), layout_(detectDatasetLayout(dir)) {
  internal::DatasetListing listing;
  switch (layout_) {
    case DatasetLayout::kTum:
      listing = internal::listTum(dir);
      break;
    case DatasetLayout::kSevenScenes:
      listing = internal::listSevenScenes(dir);
      break;
    case DatasetLayout::kRedwood:
      listing = internal::listRedwood(dir);
      break;
    case DatasetLayout::kSlambook:
      listing = internal::listSlambook(dir);
      break;
  }
  entries_ = std::move(listing.entries);
  max_depth_is_invalid_ = listing.max_depth_is_invalid;
  depth_units_per_m_ = options.depth_units_per_m.value_or(listing.depth_units_per_m);
  if (!(depth_units_per_m_ > 0.0)) {
    throw core::ConfigError(
        fmt::format("{}: depth units per metre must be positive", dir.string()));
  }

  // Intrinsics, most specific first: the command line, a tessera intrinsics.yaml in the
  // folder, what the layout's own files (or the folder name) say.
  if (options.intrinsics) {
    intrinsics_ = *options.intrinsics;
    intrinsics_origin_ = "--intrinsics";
  } else if (fs::exists(dir / "intrinsics.yaml")) {
    intrinsics_ = core::loadIntrinsicsYaml(dir / "intrinsics.yaml");
    intrinsics_origin_ = (dir / "intrinsics.yaml").string();
  } else if (listing.intrinsics) {
    intrinsics_ = *listing.intrinsics;
    intrinsics_origin_ = listing.intrinsics_origin;
  } else {
    throw core::ConfigError(fmt::format(
        "{}: this {} folder carries no camera intrinsics; pass --intrinsics fx,fy,cx,cy "
        "(or a YAML file), or put an intrinsics.yaml in the folder",
        dir.string(), layoutName(layout_)));
  }
  if (entries_.empty()) {
    throw core::SourceError(
        fmt::format("{}: the {} index lists no frames", dir.string(), layoutName(layout_)));
  }
  spdlog::info("{}: {} layout, {} frames, {} with ground-truth pose", dir.string(),
               layoutName(layout_), entries_.size(), framesWithPose());
  spdlog::info("intrinsics {} from {}; depth {} units per metre", intrinsics_.describe(),
               intrinsics_origin_, depth_units_per_m_);
}

std::size_t DatasetSource::framesWithPose() const {
  std::size_t n = 0;
  for (const auto& entry : entries_) n += entry.T_W_C.has_value() ? 1 : 0;
  return n;
}

core::ReadResult DatasetSource::read() {
  core::ReadResult result;
  if (next_ >= entries_.size()) return result;  // kEndOfData
  const std::size_t index = next_++;
  const DatasetEntry& entry = entries_[index];
  result.status = core::ReadStatus::kBadFrame;

  cv::Mat raw_depth;
  cv::Mat bgr;
  try {
    raw_depth = cv::imread(entry.depth.string(), cv::IMREAD_ANYDEPTH);
    bgr = cv::imread(entry.rgb.string(), cv::IMREAD_COLOR);
  } catch (const cv::Exception& e) {
    result.problem = fmt::format("frame {}: image decoding failed: {}", index, e.what());
    return result;
  }
  if (raw_depth.empty()) {
    result.problem =
        fmt::format("frame {}: depth image {} is missing or corrupt", index, entry.depth.string());
    return result;
  }
  if (raw_depth.type() != CV_16UC1) {
    result.problem = fmt::format("frame {}: depth image {} is not 16-bit single-channel", index,
                                 entry.depth.string());
    return result;
  }
  if (bgr.empty()) {
    result.problem =
        fmt::format("frame {}: colour image {} is missing or corrupt", index, entry.rgb.string());
    return result;
  }
  if (intrinsics_.width == 0) {  // size not given anywhere: take it from the first image
    intrinsics_.width = raw_depth.cols;
    intrinsics_.height = raw_depth.rows;
  }
  if (raw_depth.cols != intrinsics_.width || raw_depth.rows != intrinsics_.height) {
    result.problem = fmt::format("frame {}: depth image {} is {}x{}, the intrinsics say {}x{}",
                                 index, entry.depth.string(), raw_depth.cols, raw_depth.rows,
                                 intrinsics_.width, intrinsics_.height);
    return result;
  }

  if (max_depth_is_invalid_) raw_depth.setTo(0, raw_depth == 65535);
  core::Frame& frame = result.frame;
  if (depth_units_per_m_ == 1000.0) {
    frame.depth_mm = raw_depth;
  } else {
    raw_depth.convertTo(frame.depth_mm, CV_16U, 1000.0 / depth_units_per_m_);
  }
  cv::cvtColor(bgr, frame.rgb, cv::COLOR_BGR2RGB);
  frame.index = index;
  frame.timestamp_ns = entry.timestamp_ns;
  frame.colour_timestamp_ns = entry.colour_timestamp_ns;
  frame.intrinsics = intrinsics_;
  frame.T_W_C_gt = entry.T_W_C;
  result.status = core::ReadStatus::kFrame;
  return result;
}

}  // namespace tessera::drivers
