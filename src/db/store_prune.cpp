#include "tessera/db/store_prune.h"

#include <cstdint>
#include <map>
#include <set>
#include <vector>

namespace tessera::db {

PruneReport pruneUnused(TextureStore& store) {
  std::set<std::int64_t> finished;
  for (const RunRecord& run : store.runs()) {
    if (run.finished) finished.insert(run.id);
  }
  PruneReport report;
  std::map<std::int64_t, std::vector<std::int64_t>> unused;  // run -> its unused textures
  std::map<std::int64_t, std::size_t> png_bytes;
  for (const TextureSummary& t : store.textures()) {
    if (t.uses > 0 || t.run_id == 0) continue;  // used, or imported
    if (finished.count(t.run_id) == 0) {
      ++report.kept_unfinished;
      continue;
    }
    unused[t.run_id].push_back(t.id);
    png_bytes[t.id] = t.png_bytes;
  }
  for (const auto& [run, ids] : unused) {
    for (const std::int64_t id : store.removeUnused(run, ids)) {
      ++report.removed;
      report.png_bytes += png_bytes[id];
    }
  }
  report.textures_left = store.stats().textures;
  return report;
}

}  // namespace tessera::db
