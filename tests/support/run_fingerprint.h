#pragma once
// What a run decided, without what depends on timing: the texture database's textures (by
// content key) and instances, and report.json's figures but timings, memory and paths. Two
// runs of the same frames must give the same text whatever their thread count (the C++ twin
// of scripts/run_fingerprint.py).
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "tessera/db/texture_store.h"

namespace tessera::test {

inline std::string runFingerprint(const std::filesystem::path& run_dir) {
  std::ostringstream out;
  db::OpenOptions read_only;
  read_only.create = false;
  read_only.read_only = true;
  const auto store = db::openTextureStore((run_dir / "textures.db").string(), read_only);
  std::map<std::int64_t, std::string> keys;
  std::set<std::string> textures;
  for (const db::TextureSummary& summary : store->textures()) {
    const auto record = store->texture(summary.id);
    if (!record) continue;
    keys[summary.id] = record->content_key;
    std::string lattice = "none";
    if (record->lattice) {
      lattice =
          fmt::format("{:.6f} {:.6f} {:.6f} {:.6f}", record->lattice->v1.x(),
                      record->lattice->v1.y(), record->lattice->v2.x(), record->lattice->v2.y());
    }
    textures.insert(fmt::format("texture {} {} {}x{} {} patch {}", record->content_key,
                                db::kindName(record->kind), record->rgb.cols, record->rgb.rows,
                                lattice, record->source_patch));
  }
  for (const std::string& line : textures) out << line << '\n';
  std::set<std::string> instances;
  for (const db::TextureInstance& i : store->instances()) {
    const core::Similarity2& s = i.transform;
    instances.insert(
        fmt::format("instance patch {} v{} layer {} texture {} [{:.6f} {:.6f} "
                    "{:.4f} {:.4f}] psnr {} reused {}",
                    i.patch_id, i.version, i.layer, keys[i.texture_id], s.a, s.b, s.tx, s.ty,
                    i.psnr_db ? fmt::format("{:.4f}", *i.psnr_db) : "-", i.reused));
  }
  for (const std::string& line : instances) out << line << '\n';
  std::ifstream report_file(run_dir / "report.json");
  nlohmann::json report = nlohmann::json::parse(report_file);
  for (const char* timing : {"wall_s",
                             "fps",
                             "end_to_end_s",
                             "fps_end_to_end",
                             "peak_rss_mb",
                             "rss_growth_mb_per_1000_frames",
                             "latency_ms_p50",
                             "latency_ms_p95",
                             "commit_latency_ms_p50",
                             "commit_latency_ms_p95",
                             "describe_queued_ms_p50",
                             "describe_queued_ms_p95",
                             "commit_queued_ms_p50",
                             "commit_queued_ms_p95",
                             "db_commit_ms_p50",
                             "db_commit_ms_p95",
                             "match_ms_p50",
                             "bitmap_ms_per_m2",
                             "pose_graph_ms",
                             "loop_keyframe_ms",
                             "loop_keyframe_cpu_ms",
                             "loop_information_ms",
                             "loop_place_lookup_ms",
                             "loop_place_index_ms",
                             "loop_verification_ms",
                             "loop_follow_ms",
                             "loop_follow_frame_ms_max",
                             "loop_wait_s",
                             "stages",
                             "db",
                             "source",
                             "cpu_s_stream",
                             "cpu_ms_per_frame",
                             "cpu_cores_stream",
                             "cpu_s_end_of_stream",
                             "cpu_s_finish",
                             "cpu_s_total"}) {
    report.erase(timing);
  }
  out << report.dump(1) << '\n';
  return out.str();
}

}  // namespace tessera::test
