#pragma once
// What a corrected TSDF is rebuilt from. A TSDF cannot move what it fused: after loop closure
// moves the keyframes, its surface stays where the drifting poses put it. The log keeps one
// integrated frame per keyframe (depth and colour at the integration resolution, on disk, so
// that memory does not grow with the walk) with its tracked pose; at the end of a run the
// volume is fused again from them, each at its pose moved by the correction of its keyframe.
//
// Not thread-safe: owned by the integration stage, which runs serially.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "tessera/core/frame.h"
#include "tessera/core/pose.h"
#include "tessera/fusion/tsdf_map.h"

namespace tessera::fusion {

class ReintegrationLog {
 public:
  // Frames go to `dir` (created, and removed with the log), at 1/scale of their resolution.
  ReintegrationLog(std::filesystem::path dir, int scale);
  ~ReintegrationLog();
  ReintegrationLog(const ReintegrationLog&) = delete;
  ReintegrationLog& operator=(const ReintegrationLog&) = delete;

  // Keeps `frame`, fused at T_W_C; `anchor_ns` names the keyframe whose correction it follows
  // (the one it was tracked against). A frame that cannot be written (a full disk) turns the log
  // off with one warning naming the folder: the run goes on, and rebuild() is refused.
  void keep(const core::Frame& frame, const core::Isometry& T_W_C, std::int64_t anchor_ns);

  std::size_t size() const { return entries_.size(); }
  bool usable() const { return error_.empty(); }
  const std::string& error() const { return error_; }
  std::size_t diskBytes() const { return disk_bytes_; }

  // A TSDF fused from every kept frame at correction(anchor_ns) * T_W_C, as `config` fuses
  // (blocks behind released as the frames go, so memory stays that of one live volume); a
  // frame whose correction is nothing is left out (its segment is not in the map).
  // Throws core::Error when the log is not usable or a kept frame cannot be read back.
  SurfaceMesh rebuild(
      const TsdfConfig& config,
      const std::function<std::optional<core::Isometry>(std::int64_t)>& correction) const;

 private:
  struct Entry {
    std::int64_t anchor_ns = 0;
    core::Isometry T_W_C = core::Isometry::Identity();
    core::Intrinsics intrinsics;  // of the stored images
    std::filesystem::path depth, colour;
  };
  std::filesystem::path dir_;
  int scale_;
  std::vector<Entry> entries_;
  std::size_t disk_bytes_ = 0;
  std::string error_;
};

}  // namespace tessera::fusion
