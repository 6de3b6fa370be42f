#include "tessera/db/store_copy.h"

#include <map>

#include <fmt/format.h>

namespace tessera::db {

namespace {

constexpr std::size_t kTexturesPerCommit = 32;

// The copy's name for a run: its source, and what tells it from other runs of that source
// (not where it was copied from, which can be spelled many ways).
std::string copiedRunSource(const RunRecord& run) {
  return fmt::format("{} [copied: run {} started {}]", run.source, run.id, run.started_utc);
}

}  // namespace

CopyReport copyStore(const TextureStore& from, TextureStore& to, const CopyProgress& progress) {
  CopyReport report;
  // Runs first: textures and instances name them.
  std::map<std::string, std::int64_t> existing_runs;
  for (const RunRecord& run : to.runs()) existing_runs[run.source] = run.id;
  std::map<std::int64_t, std::int64_t> run_ids;
  std::vector<std::int64_t> to_finish;
  for (const RunRecord& run : from.runs()) {
    const std::string source = copiedRunSource(run);
    if (const auto it = existing_runs.find(source); it != existing_runs.end()) {
      run_ids[run.id] = it->second;
      ++report.runs_already_there;
    } else {
      run_ids[run.id] = to.beginRun(source);
      ++report.runs_copied;
    }
    if (run.finished) to_finish.push_back(run_ids[run.id]);
  }

  std::map<std::int64_t, std::int64_t> texture_ids;
  const std::vector<TextureSummary> summaries = from.textures();
  Commit batch;
  std::vector<std::int64_t> batch_sources;  // `from` ids of batch.textures
  const auto flush = [&] {
    if (batch.textures.empty()) return;
    const std::vector<std::int64_t> ids = to.commit(batch);
    for (std::size_t i = 0; i < ids.size(); ++i) texture_ids[batch_sources[i]] = ids[i];
    report.textures_copied += ids.size();
    batch = {};
    batch_sources.clear();
  };
  for (std::size_t done = 0; done < summaries.size(); ++done) {
    const std::int64_t id = summaries[done].id;
    std::optional<TextureRecord> record = from.texture(id);
    if (!record) continue;  // removed meanwhile
    if (const auto stored = to.findByContentKey(record->content_key)) {
      texture_ids[id] = *stored;
      ++report.textures_already_there;
    } else {
      const auto run = run_ids.find(record->run_id);
      record->run_id = run != run_ids.end() ? run->second : 0;
      batch.textures.push_back(std::move(*record));
      batch_sources.push_back(id);
      if (batch.textures.size() == kTexturesPerCommit) flush();
    }
    if (progress) progress(done + 1, summaries.size());
  }
  flush();

  // Instances, one commit per run: a run's map arrives whole or not at all.
  std::map<std::int64_t, Commit> per_run;
  for (TextureInstance instance : from.instances()) {
    const auto run = run_ids.find(instance.run_id);
    const auto texture = texture_ids.find(instance.texture_id);
    if (run == run_ids.end() || texture == texture_ids.end()) continue;
    instance.run_id = run->second;
    instance.texture_id = texture->second;
    per_run[instance.run_id].instances.push_back(instance);
  }
  for (const auto& [run, commit] : per_run) {
    to.commit(commit);
    report.instances_copied += commit.instances.size();
  }
  for (const std::int64_t run : to_finish) to.finishRun(run);
  return report;
}

}  // namespace tessera::db
