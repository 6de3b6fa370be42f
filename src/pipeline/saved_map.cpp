#include "internal/saved_map.h"

#include <fcntl.h>  // AT_FDCWD
#include <cstdio>   // renameat2

#include <algorithm>
#include <chrono>
#include <fstream>
#include <set>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "internal/run_parts.h"
#include "tessera/core/error.h"
#include "tessera/core/output_file.h"
#include "tessera/db/texture_store.h"
#include "tessera/fusion/map_keyframes.h"

namespace tessera::pipeline::internal {

namespace {

using nlohmann::json;
namespace fs = std::filesystem;

constexpr int kFormat = 1;

json vector2(const Eigen::Vector2d& v) { return json::array({v.x(), v.y()}); }
Eigen::Vector2d vector2(const json& j) { return {j.at(0).get<double>(), j.at(1).get<double>()}; }

json bindingJson(const planes::TextureBinding& b) {
  return {{"version", b.version},
          {"image", b.image},
          {"state_image", b.state_image},
          {"texel_m", b.texel_m},
          {"origin_uv", vector2(b.origin_uv)},
          {"x_axis", vector2(b.x_axis)},
          {"y_axis", vector2(b.y_axis)},
          {"width", b.width},
          {"height", b.height},
          {"observed", b.observed},
          {"inpainted", b.inpainted}};
}

planes::TextureBinding bindingOf(const json& j) {
  planes::TextureBinding b;
  b.version = j.at("version").get<int>();
  b.image = j.at("image").get<std::string>();
  b.state_image = j.at("state_image").get<std::string>();
  b.texel_m = j.at("texel_m").get<double>();
  b.origin_uv = vector2(j.at("origin_uv"));
  b.x_axis = vector2(j.at("x_axis"));
  b.y_axis = vector2(j.at("y_axis"));
  b.width = j.at("width").get<int>();
  b.height = j.at("height").get<int>();
  b.observed = j.at("observed").get<std::size_t>();
  b.inpainted = j.at("inpainted").get<std::size_t>();
  return b;
}

json instanceJson(const db::TextureInstance& i) {
  json j = {{"run_id", i.run_id},
            {"patch_id", i.patch_id},
            {"version", i.version},
            {"layer", i.layer},
            {"texture_id", i.texture_id},
            {"transform", {i.transform.a, i.transform.b, i.transform.tx, i.transform.ty}},
            {"reused", i.reused}};
  if (i.psnr_db) j["psnr_db"] = *i.psnr_db;
  return j;
}

db::TextureInstance instanceOf(const json& j) {
  db::TextureInstance i;
  i.run_id = j.at("run_id").get<std::int64_t>();
  i.patch_id = j.at("patch_id").get<int>();
  i.version = j.at("version").get<int>();
  i.layer = j.at("layer").get<int>();
  i.texture_id = j.at("texture_id").get<std::int64_t>();
  const json& t = j.at("transform");
  i.transform = {t.at(0).get<double>(), t.at(1).get<double>(), t.at(2).get<double>(),
                 t.at(3).get<double>()};
  i.reused = j.at("reused").get<bool>();
  if (j.contains("psnr_db")) i.psnr_db = j.at("psnr_db").get<double>();
  return i;
}

json readJson(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw core::Error(fmt::format("{}: missing", path.string()));
  try {
    return json::parse(in);
  } catch (const json::exception& e) {
    throw core::Error(fmt::format("{}: corrupt ({})", path.string(), e.what()));
  }
}

void writeJson(const json& j, const fs::path& path) {
  std::ofstream out = core::createOutputFile(path);
  out << j.dump(1) << '\n';
  core::finishOutputFile(out, path);
}

// Puts the folder `saving` in the place of `dir`, with `dir`'s old content removed. Where the
// file system can, the two trade places in one step; elsewhere `dir` is first renamed to `old`,
// and a run killed between the two renames leaves `old` whole (readSavedMap reads it then).
void swapIn(const fs::path& saving, const fs::path& dir, const fs::path& old) {
  std::error_code ignored;
  // A swap cut off between its renames: its map is the one to keep until the new one is in.
  if (!fs::exists(dir) && fs::is_directory(old)) fs::rename(old, dir);
  fs::remove_all(old, ignored);
  if (fs::exists(dir) &&
      renameat2(AT_FDCWD, saving.c_str(), AT_FDCWD, dir.c_str(), RENAME_EXCHANGE) == 0) {
    fs::remove_all(saving, ignored);  // now the earlier map
    return;
  }
  if (fs::exists(dir)) fs::rename(dir, old);
  fs::rename(saving, dir);
  fs::remove_all(old, ignored);
}

}  // namespace

SavedMap readSavedMap(const fs::path& run_dir, const planes::PatchMapConfig& config,
                      const fs::path& spill_dir, const std::optional<std::string>& database) {
  fs::path dir = run_dir / "map";
  // A run killed between the two renames of a swap left its earlier map as map.old.
  const bool swap_cut_off = !fs::is_directory(dir) && fs::is_directory(run_dir / "map.old");
  if (swap_cut_off) dir = run_dir / "map.old";
  if (!fs::is_directory(dir)) {
    throw core::Error(fmt::format(
        "{}: no saved map to continue (a run writes one in OUT/map when it ends)", dir.string()));
  }
  const fs::path session_file = dir / "session.json";
  const json session = readJson(session_file);
  SavedMap map;
  try {
    const int format = session.at("format").get<int>();
    if (format > kFormat) {
      throw core::Error(
          fmt::format("{}: written by a newer tessera (map format {}, this one reads up to {})",
                      session_file.string(), format, kFormat));
    }
    map.sessions = session.at("sessions").get<int>();
    map.database = db::lastingLocation(session.at("database").get<std::string>());
    const json bitmaps = readJson(dir / "bitmaps.json");
    for (const json& patch : bitmaps.at("patches")) {
      const int id = patch.at("id").get<int>();
      if (patch.contains("bitmap")) map.bitmaps[id] = bindingOf(patch.at("bitmap"));
      for (const json& layer : patch.at("layers")) map.instances[id].push_back(instanceOf(layer));
    }
  } catch (const json::exception& e) {
    throw core::Error(fmt::format("{}: corrupt ({})", dir.string(), e.what()));
  }
  if (database && db::lastingLocation(*database) != map.database) {
    throw core::Error(fmt::format(
        "{}: the map was committed to the texture database {}, and --db names another ({}): "
        "continue it without --db, or with its own",
        session_file.string(), map.database, *database));
  }
  for (const auto& [id, binding] : map.bitmaps) {
    for (const std::string& file : {binding.image, binding.state_image}) {
      if (!fs::is_regular_file(dir / file)) {
        throw core::Error(fmt::format("{}: missing (the bitmap of patch {} in the saved map)",
                                      (dir / file).string(), id));
      }
    }
  }
  map.keyframes = fusion::readMapKeyframes(dir / "keyframes.bin");
  map.trajectory = core::readTumTrajectory(dir / "trajectory.txt");
  map.patches = planes::PatchMap(config);
  map.patches.setSampleSpillDir(spill_dir);
  map.patches.loadState(dir / "patch_map.bin", dir / "samples");
  if (swap_cut_off) {  // read whole: it is the map again
    spdlog::warn(
        "{}: the run that saved the map was cut off while swapping it in; the earlier "
        "map is continued",
        dir.string());
    fs::rename(dir, run_dir / "map");
  }
  map.folder = run_dir / "map";
  return map;
}

void removeSavedMap(const fs::path& run_dir) {
  bool removed = false;
  for (const char* name : {"map", "map.old", "map.saving"}) {
    std::error_code ec;
    removed = fs::remove_all(run_dir / name, ec) > 0 || removed;
    if (ec) {
      throw core::Error(fmt::format("{}: the saved map of an earlier run cannot be removed: {}",
                                    (run_dir / name).string(), ec.message()));
    }
  }
  if (removed) {
    spdlog::info("{}: the map an earlier run saved here is removed (this run does not continue it)",
                 (run_dir / "map").string());
  }
}

void continueMap(RunParts& parts, SavedMap& earlier) {
  std::map<int, std::size_t> texels;
  for (const auto& [id, binding] : earlier.bitmaps) {
    texels[id] = static_cast<std::size_t>(binding.width) * binding.height;
  }
  // A patch textured again: finalized without a bitmap of its version in the map (a checkpoint
  // before its commit), or whose textures the database no longer has (a checkpoint before a
  // later version replaced them).
  std::vector<int> untextured = parts.commit.adopt(earlier.instances, texels);
  for (const planes::Patch& patch : earlier.patches.patches()) {
    const auto it = earlier.bitmaps.find(patch.id);
    if (patch.finalized && (it == earlier.bitmaps.end() || it->second.version != patch.version)) {
      untextured.push_back(patch.id);
    }
  }
  std::sort(untextured.begin(), untextured.end());
  untextured.erase(std::unique(untextured.begin(), untextured.end()), untextured.end());
  for (int id : untextured) earlier.patches.textureAgain(id);
  if (!untextured.empty()) {
    spdlog::info(
        "{} patches of the saved map have no texture in it or in the database; they "
        "are textured again",
        untextured.size());
  }
  // The run's folder shows the map's bitmaps again (a killed run may have left newer ones).
  for (const auto& [id, binding] : earlier.bitmaps) {
    for (const std::string& file : {binding.image, binding.state_image}) {
      fs::create_directories((parts.bitmaps.outDir() / file).parent_path());
      core::linkOrCopy(earlier.folder / file, parts.bitmaps.outDir() / file);
    }
  }
  parts.tracking.continueMap(earlier.keyframes);
  parts.planes.continueMap(std::move(earlier.patches));
  parts.bitmaps.adopt(earlier.bitmaps);
}

void prependEarlierTrajectory(const fs::path& run_dir, const SavedMap& earlier) {
  for (const char* name : {"trajectory.txt", "trajectory_closed.txt"}) {
    const fs::path path = run_dir / name;
    if (!fs::is_regular_file(path)) continue;
    core::Trajectory trajectory = core::readTumTrajectory(path);
    trajectory.insert(earlier.trajectory.begin(), earlier.trajectory.end());
    core::writeTumTrajectory(trajectory, path);
  }
}

MapSaver::MapSaver(fs::path run_dir, std::string database, const SavedMap* earlier,
                   double checkpoint_every_s, const PlaneStage& planes, const BitmapFiles& bitmaps,
                   const CommitStage& commit)
    : planes_(planes),
      bitmaps_(bitmaps),
      commit_(commit),
      run_dir_(std::move(run_dir)),
      database_(db::lastingLocation(database)),
      checkpoint_every_s_(checkpoint_every_s) {
  if (earlier != nullptr) {
    continued_ = true;
    earlier_sessions_ = earlier->sessions;
    keyframes_ = earlier->keyframes;
    earlier_keyframes_ = keyframes_.size();
    earlier_trajectory_ = earlier->trajectory;
  }
}

void MapSaver::addKeyframes(
    const std::vector<std::shared_ptr<const fusion::KeyframeRecord>>& keyframes) {
  const std::lock_guard lock(keyframes_mutex_);
  for (const auto& keyframe : keyframes) {
    if (keyframe->relocalisation) {
      keyframes_.push_back({keyframe->timestamp_ns, keyframe->T_W_C, keyframe->features});
    }
  }
}

void MapSaver::forgetKeyframes(const std::vector<std::int64_t>& timestamps_ns) {
  const std::set<std::int64_t> forget(timestamps_ns.begin(), timestamps_ns.end());
  const std::lock_guard lock(keyframes_mutex_);
  const auto first = keyframes_.begin() + static_cast<std::ptrdiff_t>(earlier_keyframes_);
  keyframes_.erase(std::remove_if(first, keyframes_.end(),
                                  [&](const fusion::MapKeyframe& k) {
                                    return forget.count(k.timestamp_ns) > 0;
                                  }),
                   keyframes_.end());
}

void MapSaver::checkpoint(std::int64_t frame_index) {
  last_frame_ = frame_index;
  // Not while moves within planes wait (the saved map keeps no debts): a few frames later.
  if (not_found_ || checkpoint_every_s_ <= 0.0 || planes_.map().withinPlaneMovesPending() ||
      std::chrono::duration<double>(std::chrono::steady_clock::now() - last_save_).count() <
          checkpoint_every_s_) {
    return;
  }
  try {
    write(false);
    ++checkpoints_;
  } catch (const std::exception& e) {
    spdlog::error("map checkpoint not written ({}); the earlier saved map is kept", e.what());
  }
  last_save_ = std::chrono::steady_clock::now();
}

void MapSaver::save() {
  if (not_found_) {
    spdlog::warn(
        "{}: kept as it was; this session was not found in it, and its own map (in "
        "another frame) is not saved",
        (run_dir_ / "map").string());
    return;
  }
  write(true);
}

void MapSaver::write(bool final) {
  const auto start = std::chrono::steady_clock::now();
  const fs::path dir = run_dir_ / "map";
  const fs::path saving = run_dir_ / "map.saving";
  const fs::path old = run_dir_ / "map.old";
  std::error_code ignored;
  fs::remove_all(saving, ignored);
  fs::create_directories(saving);

  const planes::PatchMap& patches = planes_.map();
  patches.saveState(saving / "patch_map.bin", saving / "samples");
  // This session's poses and keyframes in the patch map's frame: the drift measured against
  // the patches (in the poses recorded, PlaneStage::process) and the loop correction the plane
  // stage follows, read once.
  const auto loop_correction = planes_.loopCorrection();
  core::Trajectory trajectory = trajectory_;
  if (loop_correction) {
    for (auto& [t, pose] : trajectory) pose = loop_correction->at(t) * pose;
  }
  std::vector<fusion::MapKeyframe> keyframes;
  {
    const std::lock_guard lock(keyframes_mutex_);
    keyframes = keyframes_;
  }
  std::vector<fusion::MapKeyframe> in_map(
      keyframes.begin(), keyframes.begin() + static_cast<std::ptrdiff_t>(earlier_keyframes_));
  for (std::size_t i = earlier_keyframes_; i < keyframes.size(); ++i) {
    fusion::MapKeyframe& keyframe = keyframes[i];
    if (const auto pose = trajectory.find(keyframe.timestamp_ns); pose != trajectory.end()) {
      keyframe.T_W_C = pose->second;
    } else if (loop_correction && loop_correction->inMap(keyframe.timestamp_ns)) {
      keyframe.T_W_C = loop_correction->at(keyframe.timestamp_ns) * keyframe.T_W_C;
    } else {
      // A keyframe of a segment held apart sits at a guessed pose: a later session found
      // against it would start in the wrong place.
      continue;
    }
    in_map.push_back(std::move(keyframe));
  }
  keyframes = std::move(in_map);
  fusion::writeMapKeyframes(saving / "keyframes.bin", keyframes);
  trajectory.insert(earlier_trajectory_.begin(), earlier_trajectory_.end());
  core::writeTumTrajectory(trajectory, saving / "trajectory.txt");

  // Each patch's bitmap and layers of its current version; a patch whose commit has not
  // caught up has none, and a session that continues the map textures it again. The map
  // holds its own names for the bitmaps' files: the run's are replaced by newer versions. A
  // patch waiting for its next version (grown, merged, or moved within its plane after a loop
  // closure; at the end one under the area bound never gets it) has none: its bitmap is stale,
  // and the run's export drops its files.
  std::map<int, int> versions;
  for (const planes::Patch& patch : patches.patches()) {
    if (patch.finalized) versions[patch.id] = patch.version;
  }
  const planes::TextureBindings bitmaps = bitmaps_.linkCurrentInto(saving, versions);
  const auto instances = commit_.instancesNow();
  json list = json::array();
  for (const planes::Patch& patch : patches.patches()) {
    json entry = {{"id", patch.id}, {"layers", json::array()}};
    if (const auto it = bitmaps.find(patch.id);
        it != bitmaps.end() && it->second.version == patch.version) {
      entry["bitmap"] = bindingJson(it->second);
    }
    if (const auto it = instances.find(patch.id); it != instances.end() && !it->second.empty() &&
                                                  it->second.front().version == patch.version) {
      for (const db::TextureInstance& layer : it->second) {
        entry["layers"].push_back(instanceJson(layer));
      }
    }
    list.push_back(std::move(entry));
  }
  writeJson({{"patches", std::move(list)}}, saving / "bitmaps.json");
  json session = {{"format", kFormat},
                  {"sessions", earlier_sessions_ + 1},
                  {"database", database_},
                  {"keyframes", keyframes.size()},
                  {"planes", patches.planes().size()},
                  {"patches", patches.patches().size()},
                  {"last_frame", nullptr}};
  if (last_frame_) session["last_frame"] = *last_frame_;
  writeJson(session, saving / "session.json");
  // The TSDF's surface: a copy of the run's exported mesh at the end (OUT/mesh.ply is written
  // again by the next run); a checkpoint of a continued map carries the earlier sessions' (the
  // TSDF of a session cut short is lost). Files in the map never change once written, so a
  // second name for one is enough.
  if (final && fs::is_regular_file(run_dir_ / "mesh.ply")) {
    fs::copy_file(run_dir_ / "mesh.ply", saving / "mesh.ply");
  } else if (!final && continued_ && fs::is_regular_file(dir / "mesh.ply")) {
    fs::create_hard_link(dir / "mesh.ply", saving / "mesh.ply", ignored);
    if (ignored) fs::copy_file(dir / "mesh.ply", saving / "mesh.ply");
  }

  // The new map in, the old one out: at each moment one whole map is there.
  swapIn(saving, dir, old);
  spdlog::info("map saved for --continue in {} ({} keyframes, {} patches, session {}) in {:.2f} s",
               dir.string(), keyframes.size(), patches.patches().size(), earlier_sessions_ + 1,
               std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
}

}  // namespace tessera::pipeline::internal
