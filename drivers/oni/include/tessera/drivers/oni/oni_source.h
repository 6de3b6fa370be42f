#pragma once
// Plays .oni recordings through the real OpenNI2 library and its file driver.
#include <filesystem>
#include <map>
#include <memory>
#include <optional>

#include "tessera/core/frame_source.h"

namespace tessera::drivers::oni {

struct OniSourceOptions {
  std::optional<core::Intrinsics> intrinsics;  // overrides the sidecar and the file's FOV
  int frame_timeout_ms = 2000;  // a frame that does not arrive in time ends the stream
};

// The ground-truth sidecar of a recording: OUT.oni -> OUT.gt.json.
std::filesystem::path groundTruthPath(const std::filesystem::path& oni);

// Reads frames in manual playback (one frame per request, none skipped) and pairs depth with
// colour by timestamp. Intrinsics come from --intrinsics, else the sidecar, else the file's
// field of view (principal point at the image centre). A truncated or corrupt file plays what
// it can, then ends with a message naming the file and the last good frame.
// Not thread-safe (one reader).
class OniSource : public core::FrameSource {
 public:
  // Throws core::SourceError naming the file when OpenNI2 cannot open it.
  explicit OniSource(const std::filesystem::path& path, const OniSourceOptions& options = {});
  ~OniSource() override;

  core::ReadResult read() override;
  std::string name() const override { return path_.string(); }
  std::optional<std::size_t> frameCount() const override;

  // Starts again from the first frame (by reopening the file: OpenNI2's seek is unreliable).
  void rewind();

  const core::Intrinsics& intrinsics() const { return intrinsics_; }
  const std::string& intrinsicsOrigin() const { return intrinsics_origin_; }
  bool hasColour() const;

 private:
  struct Device;
  void open();
  void closeDevice();
  // The end-of-playback message of a truncated file ("" for a whole one).
  std::string truncationEnd() const;

  std::filesystem::path path_;
  OniSourceOptions options_;
  std::unique_ptr<Device> device_;
  core::Intrinsics intrinsics_;
  std::string intrinsics_origin_;
  std::map<std::int64_t, core::Isometry> poses_by_timestamp_us_;
  std::optional<core::ColourCamera> colour_camera_;  // from the sidecar, for unregistered colour
  std::size_t frames_out_ = 0;
  bool ended_ = false;
  std::filesystem::path salvage_copy_;  // playable copy of a truncated file, removed at the end
  std::string truncation_;              // what is wrong with a truncated file, else empty
};

}  // namespace tessera::drivers::oni
