#pragma once
// A run's map saved for a later session to continue (`tessera run SOURCE --continue DIR`), in
// DIR/map: the keyframes to relocalise against, the patch map (planes, tiles, cells, colour
// samples), each patch's bitmap and database instances, and the database it was committed to.
// The folder is written whole beside the old one and then swapped in, so that a run cut off
// while saving leaves the earlier map.
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "tessera/db/texture_record.h"
#include "tessera/fusion/tracker.h"
#include "tessera/planes/patch_map.h"
#include "tessera/planes/texture_binding.h"

namespace tessera::pipeline::internal {

struct RunParts;

struct SavedMap {
  int sessions = 0;      // runs that built the map
  std::string database;  // the texture database its instances name
  std::vector<fusion::MapKeyframe> keyframes;
  planes::PatchMap patches{planes::PatchMapConfig{}};
  planes::TextureBindings bitmaps;  // each patch's newest bitmap (its files in DIR)
  std::map<int, std::vector<db::TextureInstance>> instances;  // each patch's newest layers
};

// The map saved in `run_dir`; its colour samples are copied to `spill_dir`. Throws
// core::Error naming what is missing, corrupt or written by a newer tessera; nothing in
// `run_dir` is changed.
SavedMap readSavedMap(const std::filesystem::path& run_dir, const planes::PatchMapConfig& config,
                      const std::filesystem::path& spill_dir);

// Gives the run's stages the earlier map: keyframes to the tracker, patches to the plane
// stage, bitmaps and instances to the files and commit stages.
void continueMap(RunParts& parts, SavedMap& earlier);

// Saves the run's map in `run_dir`/map once the run is exported. `earlier`: the map the run
// continued (its keyframes keep their poses). Throws core::Error naming a file that cannot be
// written; the earlier map is kept then.
void saveMap(RunParts& parts, const std::filesystem::path& run_dir, const SavedMap* earlier);

}  // namespace tessera::pipeline::internal
