#pragma once
// What a map's reuses cost the view (`tessera eval --unmatched RUN0`): the run's patches and
// those of the same run made without matching (`match.enabled: false`, every patch stored as
// its own bitmap) rendered into the same views over the same pixels; overall, and per patch
// stored through another texture (a reuse, a pattern's tile, layers).
#include <cstddef>

#include <nlohmann/json.hpp>

#include "tessera/eval/view_evaluation.h"

namespace tessera::eval {

// The report.json keys of docs/METRICS.md, from an evaluation whose model 0 is the run's map
// and model `unmatched` the unmatched run's: view_psnr_lost_db, view_psnr_lost_holdout_db,
// view_ssim_lost, view_detail_lost (the unmatched map's mean minus the run's: positive is
// lost), and view_reuse_costs, one entry per patch of `patches` (the run's patches.json) whose
// instance is reused, tiled or layered and that the training views saw: its pixels, both PSNRs
// over them and the loss, largest loss first. A patch's surfaces are its object and its
// overlays' (patch_ID_vV, patch_ID_vV_overlay_K).
nlohmann::json reuseCostFigures(const ViewEvaluation& evaluation, std::size_t unmatched,
                                const nlohmann::json& patches);

}  // namespace tessera::eval
