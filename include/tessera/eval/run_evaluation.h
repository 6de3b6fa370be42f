#pragma once
// `tessera eval RUN_DIR GT.json`: the ground-truth figures of docs/METRICS.md for one run.
#include <filesystem>

#include <nlohmann/json.hpp>

#include "tessera/core/frame_source.h"
#include "tessera/eval/plane_evaluation.h"
#include "tessera/eval/view_evaluation.h"

namespace tessera::eval {

// Reads RUN_DIR/report.json and RUN_DIR/trajectory.txt and the ground-truth sidecar, computes
// every ground-truth figure that tessera's stages make possible so far, writes them into
// RUN_DIR/report.json (other ground-truth keys stay null) and returns them.
// Throws core::Error naming the file that is missing or malformed.
// `planes` sets the bounds within which a patch matches a true plane (a map of tens of metres
// tracked to centimetres needs wider ones than a room); the figures name the bounds used.
nlohmann::json evaluateRun(const std::filesystem::path& run_dir,
                           const std::filesystem::path& ground_truth,
                           const PlaneEvaluationOptions& planes = {});

// View PSNR of a run (docs/METRICS.md): RUN_DIR/patches.obj and RUN_DIR/mesh.ply rendered at
// the poses of RUN_DIR/trajectory.txt into the frames of `frames` (the source the run read),
// over the same pixels; held-out frames as report.json's holdout_every says. Writes the figures
// into RUN_DIR/report.json and returns them. Throws core::Error naming a missing or malformed
// file.
nlohmann::json evaluateRunViews(const std::filesystem::path& run_dir, core::FrameSource& frames,
                                ViewEvaluationOptions options);

}  // namespace tessera::eval
