#pragma once
// `tessera eval RUN_DIR GT.json`: the ground-truth figures of docs/METRICS.md for one run.
#include <filesystem>

#include <nlohmann/json.hpp>

namespace tessera::eval {

// Reads RUN_DIR/report.json and RUN_DIR/trajectory.txt and the ground-truth sidecar, computes
// every ground-truth figure that tessera's stages make possible so far, writes them into
// RUN_DIR/report.json (other ground-truth keys stay null) and returns them.
// Throws core::Error naming the file that is missing or malformed.
nlohmann::json evaluateRun(const std::filesystem::path& run_dir,
                           const std::filesystem::path& ground_truth);

}  // namespace tessera::eval
