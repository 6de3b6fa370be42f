#include "internal/run_stages.h"

namespace tessera::pipeline::internal {

std::optional<CommitMessage> RunStages::commit(DescribedPatch described) {
  if (described.retired) {
    commit_.retire(*described.retired);
    return std::nullopt;
  }
  CommitMessage message;
  message.batch = described.batchInfo();
  std::optional<texture::PatchBitmap> bitmap = described.bitmap;
  message.record = commit_.process(std::move(described));
  bitmaps_.keep(std::move(bitmap));
  const CommitStage::Economy economy = commit_.economy();
  MonitorCommit& totals = message.totals;
  totals.textures_stored = commit_.texturesStored();
  totals.patterns_stored = commit_.patternsStored();
  totals.textured_patches = economy.textured_patches;
  totals.reuses = economy.reuses;
  totals.bytes_before = economy.bytes_before;
  totals.bytes_after = economy.bytes_after;
  return message;
}

}  // namespace tessera::pipeline::internal
