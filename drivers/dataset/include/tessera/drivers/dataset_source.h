#pragma once
// Recorded RGB-D dataset folders: TUM RGB-D, 7-Scenes, Redwood (Open3D test data) and the
// slambook layout. The layout is detected from the folder's contents.
#include <cstddef>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "tessera/core/frame_source.h"

namespace tessera::drivers {

enum class DatasetLayout { kTum, kSevenScenes, kRedwood, kSlambook };

std::string layoutName(DatasetLayout layout);

struct DatasetOptions {
  // Overrides whatever the folder carries or its name implies.
  std::optional<core::Intrinsics> intrinsics;
  // Raw depth units per metre (TUM 5000, millimetre formats 1000); overrides the layout's.
  std::optional<double> depth_units_per_m;
};

// Recognises the layout of `dir`. Throws core::SourceError listing the layouts tessera knows
// when the folder matches none of them.
DatasetLayout detectDatasetLayout(const std::filesystem::path& dir);

// Everything a source needs to know about one frame on disk.
struct DatasetEntry {
  std::filesystem::path rgb;
  std::filesystem::path depth;
  std::int64_t timestamp_ns = 0;                    // the depth image's
  std::optional<std::int64_t> colour_timestamp_ns;  // the colour image's, where the layout says
  std::optional<core::Isometry> T_W_C;
};

// Reads frames of a folder in order. A frame whose image is missing or corrupt comes back as
// ReadStatus::kBadFrame with the file named; it never stops the stream.
// Not thread-safe (one reader).
class DatasetSource : public core::FrameSource {
 public:
  // Throws core::SourceError (unknown layout, unreadable index files) or core::ConfigError
  // (no intrinsics available), naming the folder.
  DatasetSource(const std::filesystem::path& dir, const DatasetOptions& options = {});

  core::ReadResult read() override;
  std::string name() const override { return dir_.string(); }
  std::optional<std::size_t> frameCount() const override { return entries_.size(); }

  DatasetLayout layout() const { return layout_; }
  const core::Intrinsics& intrinsics() const { return intrinsics_; }
  // Where the intrinsics came from, e.g. "TUM freiburg1 published calibration".
  const std::string& intrinsicsOrigin() const { return intrinsics_origin_; }
  double depthUnitsPerMetre() const { return depth_units_per_m_; }
  // Frames that carry a ground-truth pose.
  std::size_t framesWithPose() const;

 private:
  std::filesystem::path dir_;
  DatasetLayout layout_;
  std::vector<DatasetEntry> entries_;
  core::Intrinsics intrinsics_;
  std::string intrinsics_origin_;
  double depth_units_per_m_ = 1000.0;
  bool max_depth_is_invalid_ = false;  // 7-Scenes marks invalid depth as 65535
  std::size_t next_ = 0;
};

}  // namespace tessera::drivers
