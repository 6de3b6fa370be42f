#include "tessera/pipeline/map_monitor.h"

#include <fmt/format.h>

#include "internal/json_values.h"

namespace tessera::pipeline {

using internal::orNull;
using internal::ratio;

void RecentMean::add(double x) {
  value = seen ? value + (x - value) / 16.0 : x;
  seen = true;
}

void MapMonitor::start(const std::string& source) {
  std::lock_guard lock(mutex_);
  now_ = MonitorSnapshot{};
  now_.state = "running";
  now_.source = source;
  history_.clear();
  history_step_s_ = 0.25;
  updated();
}

void MapMonitor::onFrame(const MonitorFrame& frame) {
  std::lock_guard lock(mutex_);
  now_.frame = frame;
  now_.tracking_ms.add(frame.figures.tracking_ms);
  now_.integration_ms.add(frame.figures.integration_ms);
  now_.planes_ms.add(frame.figures.planes_ms);
  now_.cpu_ms.add(frame.cpu_ms);
  now_.fps = frame.elapsed_s > 0.0 ? static_cast<double>(frame.frames_done) / frame.elapsed_s
                                   : 0.0;
  if (history_.empty() || frame.elapsed_s - history_.back().elapsed_s >= history_step_s_) {
    history_.push_back({frame.elapsed_s, frame.frames_done, frame.map_bytes,
                        3 * now_.commits.economy.pixels_before,
                        3 * now_.commits.economy.pixels_after});
    if (history_.size() > kMaxHistory) {
      // Keep every other point, and sample half as often from now on: memory stays bounded on
      // a run of hours, and the chart keeps its shape.
      std::vector<HistoryPoint> thinned;
      for (std::size_t i = 0; i < history_.size(); i += 2) thinned.push_back(history_[i]);
      history_ = std::move(thinned);
      history_step_s_ *= 2.0;
    }
  }
  updated();
}

void MapMonitor::onCommit(const MonitorCommit& commit) {
  std::lock_guard lock(mutex_);
  now_.commits = commit;
  now_.ccv_considered += commit.patch.ccv_considered;
  now_.ccv_removed += commit.patch.ccv_removed;
  now_.patches_committed += commit.committed ? 1 : 0;
  now_.bitmap_ms.add(commit.patch.bitmap_ms);
  now_.match_ms.add(commit.patch.match_ms);
  if (commit.committed) now_.commit_latency_ms.add(commit.patch.commit_latency_ms);
  updated();
}

void MapMonitor::finish(const nlohmann::json& report) {
  std::lock_guard lock(mutex_);
  now_.state = "finished";
  now_.report = report;
  updated();
}

MonitorSnapshot MapMonitor::snapshot() const {
  std::lock_guard lock(mutex_);
  return now_;
}

std::vector<HistoryPoint> MapMonitor::history() const {
  std::lock_guard lock(mutex_);
  return history_;
}

std::uint64_t MapMonitor::waitPast(std::uint64_t generation,
                                   std::chrono::milliseconds timeout) const {
  std::unique_lock lock(mutex_);
  changed_.wait_for(lock, timeout, [&] { return now_.generation > generation; });
  return now_.generation;
}

void MapMonitor::updated() {
  ++now_.generation;
  changed_.notify_all();
}

namespace {

nlohmann::json optionalMean(const RecentMean& mean) {
  return mean.seen ? nlohmann::json(mean.value) : nlohmann::json(nullptr);
}

}  // namespace

nlohmann::json toJson(const MonitorSnapshot& s) {
  const MonitorFrame& f = s.frame;
  const MonitorCommit& c = s.commits;
  const std::size_t bytes_before = 3 * c.economy.pixels_before;
  const std::size_t bytes_after = 3 * c.economy.pixels_after;
  nlohmann::json out = {
      {"state", s.state},
      {"generation", s.generation},
      {"source", s.source},
      {"elapsed_s", f.elapsed_s},
      {"frames", f.frames_done},
      {"frames_total", f.frames_total ? nlohmann::json(*f.frames_total) : nlohmann::json(nullptr)},
      {"fps", s.fps},
      {"frames_dropped", f.frames_dropped},
      {"pose", f.pose},
      {"frames_without_pose", f.frames_without_pose},
      {"frames_held_apart", f.frames_held_apart},
      {"latency_ms", orNull(f.figures.latency_ms)},
      {"tsdf_bytes", f.figures.tsdf_bytes},
      {"bitmap_bytes", f.bitmap_bytes},
      {"map_bytes", f.map_bytes},
      {"patches_live", f.figures.patches_live},
      {"patches_finalized", f.figures.patches_finalized},
      {"patches_committed", s.patches_committed},
      {"textures_stored", c.textures_stored},
      {"patterns_stored", c.patterns_stored},
      {"textured_patches", c.economy.textured_patches},
      {"reuses", c.economy.reuses},
      {"bytes_before", bytes_before},
      {"bytes_after", bytes_after},
      {"compression", orNull(ratio(bytes_before, bytes_after))},
      {"ccv_considered", s.ccv_considered},
      {"ccv_rejection", orNull(ratio(s.ccv_removed, s.ccv_considered))},
      {"stage_ms",
       {{"tracking", optionalMean(s.tracking_ms)},
        {"integration", optionalMean(s.integration_ms)},
        {"planes", optionalMean(s.planes_ms)},
        {"bitmap", optionalMean(s.bitmap_ms)},
        {"match", optionalMean(s.match_ms)}}},
      {"commit_latency_ms", optionalMean(s.commit_latency_ms)},
      {"cpu_ms_per_frame", optionalMean(s.cpu_ms)},
      {"cpu_s", f.cpu_s},
      {"rss_mb", f.rss_mb},
  };
  if (!s.report.is_null()) out["report"] = s.report;
  return out;
}

nlohmann::json toJson(const std::vector<HistoryPoint>& history) {
  nlohmann::json points = nlohmann::json::array();
  for (const HistoryPoint& p : history) {
    points.push_back({{"elapsed_s", p.elapsed_s},
                      {"frames", p.frames},
                      {"map_bytes", p.map_bytes},
                      {"bytes_before", p.bytes_before},
                      {"bytes_after", p.bytes_after}});
  }
  return points;
}

namespace {

// Prometheus text format: a family's HELP and TYPE lines, then its samples.
class Exposition {
 public:
  void family(const char* name, const char* type, const char* help) {
    out_ += fmt::format("# HELP {} {}\n# TYPE {} {}\n", name, help, name, type);
  }
  void sample(const char* name, double value, const std::string& labels = {}) {
    out_ += fmt::format("{}{} {}\n", name, labels.empty() ? "" : "{" + labels + "}", value);
  }
  void one(const char* name, const char* type, const char* help, double value) {
    family(name, type, help);
    sample(name, value);
  }
  std::string take() { return std::move(out_); }

 private:
  std::string out_;
};

double count(std::size_t n) { return static_cast<double>(n); }

}  // namespace

std::string toPrometheus(const MonitorSnapshot& s) {
  const MonitorFrame& f = s.frame;
  const MonitorCommit& c = s.commits;
  Exposition e;
  e.family("tessera_run_state", "gauge", "1 for the run's current state, 0 for the others");
  for (const char* state : {"idle", "running", "finished"}) {
    e.sample("tessera_run_state", s.state == state ? 1.0 : 0.0,
             fmt::format("state=\"{}\"", state));
  }
  e.one("tessera_elapsed_seconds", "gauge", "Seconds since the run started", f.elapsed_s);
  e.one("tessera_frames_total", "counter", "Frames through the pipeline", count(f.frames_done));
  if (f.frames_total) {
    e.one("tessera_frames_expected", "gauge", "Frames the recording holds (replay only)",
          count(*f.frames_total));
  }
  e.one("tessera_frames_dropped_total", "counter",
        "Live frames the busy pipeline never read", count(f.frames_dropped));
  e.one("tessera_frames_without_pose_total", "counter",
        "Frames not fused: tracking lost, or no pose given", count(f.frames_without_pose));
  e.one("tessera_frames_held_apart_total", "counter",
        "Frames tracked in a segment not joined to the map, neither fused nor textured",
        count(f.frames_held_apart));
  e.one("tessera_frames_per_second", "gauge", "Frames through the pipeline over elapsed time",
        s.fps);
  if (f.figures.latency_ms) {
    e.one("tessera_frame_latency_seconds", "gauge",
          "Last live frame's time from capture to the end of fusion", *f.figures.latency_ms / 1e3);
  }
  e.family("tessera_stage_seconds", "gauge",
           "Recent mean time per frame (tracking, integration, planes) or per patch (bitmap, "
           "match, commit latency)");
  const std::pair<const char*, const RecentMean*> stages[] = {
      {"tracking", &s.tracking_ms}, {"integration", &s.integration_ms},
      {"planes", &s.planes_ms},     {"bitmap", &s.bitmap_ms},
      {"match", &s.match_ms},       {"commit_latency", &s.commit_latency_ms}};
  for (const auto& [name, mean] : stages) {
    if (mean->seen) e.sample("tessera_stage_seconds", mean->value / 1e3, fmt::format("stage=\"{}\"", name));
  }
  e.one("tessera_cpu_seconds_total", "counter",
        "CPU time (user + system, every thread) since the run started", f.cpu_s);
  if (s.cpu_ms.seen) {
    e.one("tessera_cpu_seconds_per_frame", "gauge", "Recent mean CPU time per frame",
          s.cpu_ms.value / 1e3);
  }
  e.one("tessera_resident_bytes", "gauge", "Resident memory of the process", f.rss_mb * 1e6);
  e.one("tessera_tsdf_bytes", "gauge", "Memory of the TSDF volume", count(f.figures.tsdf_bytes));
  e.one("tessera_bitmap_bytes", "gauge",
        "Patch bitmaps of the map, 3 bytes per texel (written to OUT/textures, not held in memory)",
        count(f.bitmap_bytes));
  e.one("tessera_map_bytes", "gauge", "The map's size: TSDF plus bitmaps", count(f.map_bytes));
  e.family("tessera_patches", "gauge", "Patches by state");
  e.sample("tessera_patches", count(f.figures.patches_live), "state=\"live\"");
  e.sample("tessera_patches", count(f.figures.patches_finalized), "state=\"finalized\"");
  e.one("tessera_patches_committed_total", "counter", "Patch versions committed to the database",
        count(s.patches_committed));
  e.one("tessera_textures_stored_total", "counter", "New textures this run stored",
        count(c.textures_stored));
  e.one("tessera_patterns_stored_total", "counter",
        "New textures this run stored as one period of a pattern", count(c.patterns_stored));
  e.one("tessera_textured_patches", "gauge", "Patches the map shows through a database texture",
        count(c.economy.textured_patches));
  e.one("tessera_texture_reuses", "gauge", "Of those, patches reusing a texture stored before",
        count(c.economy.reuses));
  e.family("tessera_texture_bytes", "gauge",
           "Texture bytes of the map's patches: before reuse (each patch its own bitmap) and "
           "after (each texture they show once)");
  const std::size_t bytes_before = 3 * c.economy.pixels_before;
  const std::size_t bytes_after = 3 * c.economy.pixels_after;
  e.sample("tessera_texture_bytes", count(bytes_before), "stage=\"before\"");
  e.sample("tessera_texture_bytes", count(bytes_after), "stage=\"after\"");
  if (const auto r = ratio(bytes_before, bytes_after)) {
    e.one("tessera_compression_ratio", "gauge", "Texture bytes before reuse over after", *r);
  }
  e.one("tessera_ccv_candidates_total", "counter",
        "Stored textures the colour coherence prefilter was asked about", count(s.ccv_considered));
  e.one("tessera_ccv_rejected_total", "counter", "Of those, the ones it removed",
        count(s.ccv_removed));
  return e.take();
}

}  // namespace tessera::pipeline
