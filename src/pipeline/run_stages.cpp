#include "internal/run_stages.h"

#include <chrono>

namespace tessera::pipeline::internal {

FusedFrame RunStages::closeLoops(FusedFrame fused) {
  if (loop_closer_ == nullptr) return fused;
  for (auto& keyframe : fused.new_keyframes) loop_closer_->add(std::move(keyframe));
  fused.new_keyframes.clear();
  fused.loop_correction = loop_closer_->correction();
  return fused;
}

std::vector<planes::PatchEvent> RunStages::finishStream(
    std::vector<planes::PatchSnapshot>& finalized) {
  if (loop_closer_ == nullptr) return planes_.finishStream(finalized);
  const auto start = std::chrono::steady_clock::now();
  loop_closer_->finish();
  loop_wait_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return planes_.finishStream(finalized, loop_closer_->correction());
}

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
  const CommitRecord& record = message.record;
  const CommitFigures& totals = commit_.figures();
  message.figures = {record.instance.has_value(),
                     record.instance && record.instance->reused,
                     record.figures,
                     totals.textures_stored,
                     totals.patterns_stored,
                     commit_.economy()};
  return message;
}

}  // namespace tessera::pipeline::internal
