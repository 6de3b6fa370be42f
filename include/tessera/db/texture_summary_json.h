#pragma once
// A stored texture's summary as JSON, as `tessera db list --json` prints it and the monitor's
// /textures serves it: one shape for both. Header-only, so the db module itself needs no JSON.
#include <nlohmann/json.hpp>

#include "tessera/db/texture_record.h"

namespace tessera::db {

inline nlohmann::json summaryJson(const TextureSummary& t) {
  return {{"id", t.id},
          {"kind", kindName(t.kind)},
          {"width", t.width},
          {"height", t.height},
          {"run_id", t.run_id},
          {"source_patch", t.source_patch},
          {"name", t.name},
          {"uses", t.uses},
          {"png_bytes", t.png_bytes}};
}

}  // namespace tessera::db
