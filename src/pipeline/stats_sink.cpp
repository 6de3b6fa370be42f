#include <chrono>
#include <fstream>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "tessera/core/cpu_time.h"
#include "tessera/core/error.h"
#include "tessera/core/memory.h"
#include "tessera/core/trajectory.h"
#include "tessera/pipeline/stages.h"
#include "tessera/pipeline/texture_db_stages.h"

namespace tessera::pipeline {

StreamFigures StatsSink::figures() const {
  StreamFigures figures;
  figures.frames = frames_done_;
  figures.interruptions = interruptions_;
  figures.latency_ms_p50 = latencies_ms_.quantile(0.50);
  figures.latency_ms_p95 = latencies_ms_.quantile(0.95);
  // How fast the resident memory grew over the second half of the frames; nothing under 200.
  if (frames_done_ >= 200) {
    const std::optional<double> slope =
        core::leastSquaresSlope(rss_mb_.points(), static_cast<double>(frames_done_ / 2));
    if (slope) figures.rss_growth_mb_per_1000_frames = 1000.0 * *slope;
  }
  figures.cpu_stream_s = cpu_last_frame_s_ - cpu_start_s_;
  figures.elapsed_stream_s = elapsed_last_frame_s_;
  return figures;
}

StatsSink::StatsSink(const std::filesystem::path& out_dir, std::optional<std::size_t> frames_total,
                     ProgressCallback on_progress, std::function<std::size_t()> bitmap_bytes)
    : stats_path_(out_dir / "stats.jsonl"),
      trajectory_path_(out_dir / "trajectory.txt"),
      stats_(stats_path_),
      trajectory_(trajectory_path_),
      frames_total_(frames_total),
      on_progress_(std::move(on_progress)),
      bitmap_bytes_(std::move(bitmap_bytes)),
      start_(std::chrono::steady_clock::now()),
      cpu_start_s_(core::processCpuSeconds()),
      cpu_last_frame_s_(cpu_start_s_) {
  for (const auto& [file, path] :
       {std::pair{&stats_, &stats_path_}, {&trajectory_, &trajectory_path_}}) {
    if (!*file) throw core::Error(fmt::format("{}: cannot be created", path->string()));
  }
  trajectory_ << "# camera poses T_W_C (tracked, corrected against the planes; in a segment held "
                 "apart from the map, as tracked): "
                 "timestamp tx ty tz qx qy qz qw\n";
}

void StatsSink::process(const FusedFrame& fused) {
  ScopedStageTime time(timer_);
  if (fused.frame.source_interrupted) {
    ++interruptions_;
    if (!write_failed_) {
      stats_ << nlohmann::json{{"type", "source"},
                               {"event", "interrupted"},
                               {"frames_done", frames_done_}}
                    .dump()
             << '\n';
      writePatchEvents(fused.patch_events);
    }
    return;
  }
  ++frames_done_;
  const bool without_pose =
      !fused.integrated && !fused.between_integrations && !fused.held_out && !fused.held_apart;
  frames_without_pose_ += without_pose ? 1 : 0;
  frames_held_apart_ += fused.held_apart ? 1 : 0;
  const FrameFigures& figures = fused.figures;
  if (figures.latency_ms) latencies_ms_.add(*figures.latency_ms);
  // The process's CPU time since the frame before: every thread's share of this frame.
  const double cpu_s = core::processCpuSeconds();
  const double cpu_ms = 1e3 * (cpu_s - cpu_last_frame_s_);
  cpu_last_frame_s_ = cpu_s;
  // A frame held apart keeps the tracker's pose here: the corrected trajectory takes it when its
  // segment is joined to the map by the end.
  const std::optional<core::Isometry> pose = fused.held_apart ? fused.T_W_C : mapPoseOf(fused);
  if (pose) estimate_[fused.frame.timestamp_ns] = *pose;
  if (fused.frame.T_W_C_gt) ground_truth_[fused.frame.timestamp_ns] = *fused.frame.T_W_C_gt;
  const std::size_t bitmap_bytes = bitmap_bytes_ ? bitmap_bytes_() : 0;
  map_bytes_ = figures.tsdf_bytes + bitmap_bytes;
  const double rss_mb = core::residentMb();
  rss_mb_.add(static_cast<double>(frames_done_ - 1), rss_mb);
  const double elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  elapsed_last_frame_s_ = elapsed_s;

  if (!write_failed_) {
    nlohmann::json line = {{"type", "frame"},
                           {"index", fused.frame.index},
                           {"timestamp_ns", fused.frame.timestamp_ns},
                           {"elapsed_s", elapsed_s},
                           {"integrated", fused.integrated},
                           {"bitmap_bytes", bitmap_bytes},
                           {"map_bytes", map_bytes_},
                           {"rss_mb", rss_mb},
                           {"cpu_ms", cpu_ms},
                           {"textures_stored", textures_stored_}};
    // About 1 ms each on a large heap: once a second at 30 frames/s.
    if (frames_done_ % 30 == 1) line["heap_mb"] = core::heapInUseMb();
    figures.addTo(line);
    if (!fused.integrated) line["skip_reason"] = fused.skip_reason;
    if (fused.colour_gain) {
      line["colour_gain"] = {(*fused.colour_gain)[0], (*fused.colour_gain)[1],
                             (*fused.colour_gain)[2]};
    }
    stats_ << line.dump() << '\n';
    writePatchEvents(fused.patch_events);
    if (pose) trajectory_ << core::tumLine(fused.frame.timestamp_ns, *pose);
    if (!stats_ || !trajectory_) {
      write_failed_ = true;
      spdlog::error("{}: writing failed (disk full?); no further stats lines",
                    stats_path_.string());
    }
  }
  if (monitor_ != nullptr) {
    MonitorFrame frame;
    frame.elapsed_s = elapsed_s;
    frame.frames_done = frames_done_;
    frame.frames_total = frames_total_;
    frame.frames_dropped = frames_dropped_ ? frames_dropped_() : 0;
    frame.pose = fused.held_apart ? "held apart" : pose ? "in map" : "lost";
    frame.frames_without_pose = frames_without_pose_;
    frame.frames_held_apart = frames_held_apart_;
    frame.figures = figures;
    frame.bitmap_bytes = bitmap_bytes;
    frame.map_bytes = map_bytes_;
    frame.cpu_ms = cpu_ms;
    frame.cpu_s = cpu_s - cpu_start_s_;
    frame.rss_mb = rss_mb;
    monitor_->onFrame(frame);
  }
  if (on_progress_) {
    on_progress_({frames_done_, frames_total_, elapsed_s, map_bytes_, figures.latency_ms});
  }
}

void StatsSink::attachMonitor(MapMonitor* monitor, std::function<std::size_t()> frames_dropped) {
  monitor_ = monitor;
  frames_dropped_ = std::move(frames_dropped);
}

void StatsSink::writePatchEvents(const std::vector<planes::PatchEvent>& events) {
  for (const planes::PatchEvent& event : events) {
    const bool finalized = event.kind == planes::PatchEvent::Kind::kFinalized;
    nlohmann::json line = {{"type", "patch"},
                           {"event", finalized ? "finalized" : "retired"},
                           {"id", event.id},
                           {"version", event.version},
                           {"frames_done", frames_done_}};
    if (finalized) line["area_m2"] = event.area_m2, line["reason"] = event.reason;
    stats_ << line.dump() << '\n';
  }
}

void StatsSink::writeCommit(const CommitMessage& message) {
  const CommitRecord& record = message.record;
  const std::size_t batch = message.batch.index, batch_size = message.batch.size;
  const std::uint64_t frame_index = message.batch.frame_index;
  const MonitorCommit& figures = message.figures;
  if (monitor_ != nullptr) monitor_->onCommit(figures);
  textures_stored_ = figures.textures_stored;
  BatchCounts& counts = batches_[batch];
  counts.patches += 1;
  counts.considered += figures.patch.ccv_considered;
  counts.removed += figures.patch.ccv_removed;
  counts.reuses += figures.reused ? 1 : 0;
  if (write_failed_) return;
  if (record.patch_id != 0 || record.instance) {
    nlohmann::json line = {{"type", "patch"},         {"event", "committed"},
                           {"id", record.patch_id},   {"version", record.version},
                           {"frame", frame_index},    {"committed", figures.committed},
                           {"method", record.method}, {"textures_stored", figures.textures_stored}};
    figures.patch.addTo(line);
    if (record.instance) {
      const core::Similarity2& s = record.instance->transform;
      line["texture_id"] = record.instance->texture_id;
      line["reused"] = figures.reused;
      line["transform"] = {s.a, s.b, s.tx, s.ty};
      line["psnr_db"] = record.instance->psnr_db ? nlohmann::json(*record.instance->psnr_db)
                                                 : nlohmann::json(nullptr);
      nlohmann::json overlays = nlohmann::json::array();
      for (const db::TextureInstance& overlay : record.overlays) {
        overlays.push_back({{"texture_id", overlay.texture_id}, {"reused", overlay.reused}});
      }
      line["overlays"] = overlays;
    }
    stats_ << line.dump() << '\n';
  }
  if (counts.patches == batch_size) {
    stats_ << nlohmann::json{{"type", "match"},
                             {"frame", frame_index},
                             {"patches", counts.patches},
                             {"ccv_considered", counts.considered},
                             {"ccv_removed", counts.removed},
                             {"reuses", counts.reuses}}
                  .dump()
           << '\n';
    batches_.erase(batch);
  }
}

void StatsSink::flush() {
  stats_.close();
  trajectory_.close();
  if (write_failed_ || stats_.fail() || trajectory_.fail()) {
    throw core::Error(fmt::format("{} or {}: could not be written completely (disk full?)",
                                  stats_path_.string(), trajectory_path_.string()));
  }
}

}  // namespace tessera::pipeline
