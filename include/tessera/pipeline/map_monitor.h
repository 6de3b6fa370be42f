#pragma once
// What a run looks like while it runs: the figures every stage emits, gathered in one place for
// the progress line, the HTTP monitor (/metrics, /stats, /events) and its page. Writers are the
// stats sink (once per frame) and the commit node (once per patch); each update is a few
// assignments under a mutex that no reader holds for longer than a copy, so watching never
// slows the stream (docs/MEASUREMENTS.md, "Watching a run").
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tessera/pipeline/stage_figures.h"
#include "tessera/reuse/map_economy.h"

namespace tessera::pipeline {

// One frame out of the pipeline (StatsSink::process).
struct MonitorFrame {
  double elapsed_s = 0.0;
  std::size_t frames_done = 0;
  std::optional<std::size_t> frames_total;
  std::size_t frames_dropped = 0;  // live sources: frames the busy pipeline never read
  // The frame's camera pose: "in map", "held apart" (a segment not joined to the map) or
  // "lost"; and the frames so far without a pose, and held apart.
  const char* pose = "lost";
  std::size_t frames_without_pose = 0, frames_held_apart = 0;
  FrameFigures figures;            // the frame's own, as its stats.jsonl line gives them
  std::size_t bitmap_bytes = 0, map_bytes = 0;
  double cpu_ms = 0.0;  // the process's CPU time since the frame before (every thread)
  double cpu_s = 0.0;   // the process's CPU time since the run started
  double rss_mb = 0.0;  // resident memory
};

// One patch through matching and commit, with the run's totals after it.
struct MonitorCommit {
  bool committed = false;
  bool reused = false;
  PatchCommitFigures patch;  // the patch's own, as its stats.jsonl line gives them
  std::size_t textures_stored = 0, patterns_stored = 0;
  reuse::Economy economy;  // the map's now: report.json's figures so far
};

// Mean of the recent values: each new one weighs 1/16 (about the last second at 30 frames/s).
struct RecentMean {
  double value = 0.0;
  bool seen = false;
  void add(double x);
};

struct MonitorSnapshot {
  std::uint64_t generation = 0;  // grows with every update
  std::string state = "idle";    // "idle" (no run: db serve), "running" or "finished"
  std::string source;
  MonitorFrame frame;
  MonitorCommit commits;  // the newest
  std::size_t patches_committed = 0;
  std::size_t ccv_considered = 0, ccv_removed = 0;    // over every commit so far
  RecentMean tracking_ms, integration_ms, planes_ms;  // per frame
  RecentMean bitmap_ms, match_ms, commit_latency_ms;  // per patch
  RecentMean cpu_ms;                                  // per frame, every thread
  double fps = 0.0;                                   // frames over elapsed time
  nlohmann::json report;                              // report.json once finished
};

// The map's size over time, for the page's chart.
struct HistoryPoint {
  double elapsed_s = 0.0;
  std::size_t frames = 0;
  std::size_t map_bytes = 0;
  std::size_t bytes_before = 0, bytes_after = 0;
};

class MapMonitor {
 public:
  // At most this many history points are kept: older ones are thinned to every other one.
  static constexpr std::size_t kMaxHistory = 2048;

  void start(const std::string& source);
  void onFrame(const MonitorFrame& frame);
  void onCommit(const MonitorCommit& commit);
  // The run is over: `report` is what report.json holds.
  void finish(const nlohmann::json& report);

  MonitorSnapshot snapshot() const;
  std::vector<HistoryPoint> history() const;
  // Waits up to `timeout` for an update past `generation`; returns the newest generation.
  std::uint64_t waitPast(std::uint64_t generation, std::chrono::milliseconds timeout) const;

 private:
  void updated();  // under mutex_

  mutable std::mutex mutex_;
  mutable std::condition_variable changed_;
  MonitorSnapshot now_;
  std::vector<HistoryPoint> history_;
  double history_step_s_ = 0.25;  // doubles each time the history is thinned
};

// The snapshot as /stats serves it: report.json's names where the two share a figure.
nlohmann::json toJson(const MonitorSnapshot& snapshot);
nlohmann::json toJson(const std::vector<HistoryPoint>& history);
// Prometheus text exposition format 0.0.4: HELP and TYPE lines, base units (bytes, seconds).
std::string toPrometheus(const MonitorSnapshot& snapshot);

}  // namespace tessera::pipeline
