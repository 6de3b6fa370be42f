#pragma once
// A run's map saved for a later session to continue (`tessera run SOURCE --continue DIR`), in
// DIR/map: the keyframes to relocalise against, the patch map (planes, tiles, cells, colour
// samples), each patch's bitmap and database instances, and the database it was committed to.
// The folder is written whole beside the old one and then swapped in, so that a run cut off
// while saving leaves the earlier map.
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "tessera/core/trajectory.h"
#include "tessera/db/texture_record.h"
#include "tessera/fusion/tracker.h"
#include "tessera/pipeline/stages.h"
#include "tessera/pipeline/texture_db_stages.h"
#include "tessera/planes/patch_map.h"
#include "tessera/planes/texture_binding.h"

namespace tessera::pipeline::internal {

struct RunParts;

struct SavedMap {
  std::filesystem::path folder;  // OUT/map
  int sessions = 0;              // runs that built the map
  std::string database;  // the texture database its instances name
  std::vector<fusion::MapKeyframe> keyframes;
  core::Trajectory trajectory;  // the camera's poses in the map, every session so far
  planes::PatchMap patches{planes::PatchMapConfig{}};
  planes::TextureBindings bitmaps;  // each patch's newest bitmap (its files in `folder`)
  std::map<int, std::vector<db::TextureInstance>> instances;  // each patch's newest layers
};

// The map saved in `run_dir` (or the earlier one a swap cut off left as map.old, which becomes
// the map again); finalized patches' colour samples are linked into `spill_dir`. Throws
// core::Error naming what is missing, corrupt or written by a newer tessera, or when
// `database` (--db) names another database than the map's; nothing in `run_dir` is changed
// then.
SavedMap readSavedMap(const std::filesystem::path& run_dir, const planes::PatchMapConfig& config,
                      const std::filesystem::path& spill_dir,
                      const std::optional<std::string>& database);

// Removes a map saved in `run_dir` (a new run there that does not continue it), saying so.
void removeSavedMap(const std::filesystem::path& run_dir);

// Gives the run's stages the earlier map: keyframes to the tracker, patches to the plane
// stage, bitmaps and instances to the files and commit stages. A patch whose texture the map
// does not hold (saved by a checkpoint before its commit) is textured again.
void continueMap(RunParts& parts, SavedMap& earlier);

// Puts the earlier sessions' poses before this session's in OUT/trajectory.txt and
// OUT/trajectory_closed.txt (where it is), so that they hold the whole map's trajectory.
void prependEarlierTrajectory(const std::filesystem::path& run_dir, const SavedMap& earlier);

// Writes OUT/map: every checkpoint_every_s on the frame path (after the plane stage, which owns
// the patch map), and at the end of the run.
class MapSaver {
 public:
  // `earlier`: the map the run continues, if any (its keyframes are kept as they were saved:
  // this session's pose graph does not hold them).
  // The map is read from the stages given, which outlive the saver.
  MapSaver(std::filesystem::path run_dir, std::string database, const SavedMap* earlier,
           double checkpoint_every_s, const PlaneStage& planes, const BitmapFiles& bitmaps,
           const CommitStage& commit);

  // The keyframes the tracker made; those it relocalises against are kept (frame path).
  void addKeyframes(const std::vector<std::shared_ptr<const fusion::KeyframeRecord>>& keyframes);
  // Drops this session's keyframes taken at these times: revisits of a kept one's place, as
  // loop closure found (LoopCloser::takeCovered).
  void forgetKeyframes(const std::vector<std::int64_t>& timestamps_ns);
  // The map's pose of a frame (frame path, after the plane stage).
  void addPose(std::int64_t timestamp_ns, const core::Isometry& T_W_C) {
    trajectory_[timestamp_ns] = T_W_C;
  }
  // Saves when checkpoint_every_s has passed since the last save (frame path, after the
  // plane stage). A save that fails is logged; the earlier map is kept.
  void checkpoint(std::int64_t frame_index);
  // The session was not found in the map it continues and maps in its own frame: the saved
  // map is kept as it was (a map of two frames would be no map), and nothing more is saved.
  void sessionNotFound() { not_found_ = true; }
  // The end of the run; throws core::Error naming a file that cannot be written.
  void save();

  std::size_t checkpoints() const { return checkpoints_; }

 private:
  // final: the end of the run (OUT/mesh.ply is written), not a checkpoint.
  void write(bool final);

  const PlaneStage& planes_;
  const BitmapFiles& bitmaps_;
  const CommitStage& commit_;

  std::filesystem::path run_dir_;
  std::string database_;
  bool continued_ = false;  // the run continues an earlier map
  int earlier_sessions_ = 0;
  double checkpoint_every_s_;
  std::chrono::steady_clock::time_point last_save_ = std::chrono::steady_clock::now();
  std::mutex keyframes_mutex_;  // added on the loop stage, read on the plane stage
  std::vector<fusion::MapKeyframe> keyframes_;
  std::size_t earlier_keyframes_ = 0;  // the first ones, kept as they were saved
  core::Trajectory earlier_trajectory_;
  core::Trajectory trajectory_;             // this session's
  std::optional<std::int64_t> last_frame_;  // the newest frame the map holds
  std::size_t checkpoints_ = 0;
  bool not_found_ = false;  // sessionNotFound()
};

}  // namespace tessera::pipeline::internal
