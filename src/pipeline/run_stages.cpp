#include "internal/run_stages.h"

#include <chrono>

#include <spdlog/spdlog.h>

#include "internal/corrected_surface.h"
#include "internal/saved_map.h"
#include "tessera/core/memory.h"

namespace tessera::pipeline::internal {

TrackedFrame RunStages::track(core::Frame frame) {
  forgetCoveredKeyframes();
  return tracking_.process(std::move(frame));
}

void RunStages::forgetCoveredKeyframes() {
  if (loop_closer_ == nullptr) return;
  const std::vector<std::int64_t> covered = loop_closer_->takeCovered();
  if (covered.empty()) return;
  tracking_.forgetKeyframes(covered);
  if (map_saver_ != nullptr) map_saver_->forgetKeyframes(covered);
}

FusedFrame RunStages::closeLoops(FusedFrame fused) {
  if (map_saver_ != nullptr) map_saver_->addKeyframes(fused.new_keyframes);
  if (loop_closer_ == nullptr) return fused;
  for (auto& keyframe : fused.new_keyframes) loop_closer_->add(std::move(keyframe));
  fused.new_keyframes.clear();
  fused.loop_correction = loop_closer_->correction();
  fused.figures.loop_keyframes_waiting = loop_closer_->waiting();
  return fused;
}

FusedFrame RunStages::findPlanes(FusedFrame fused) {
  FusedFrame out = planes_.process(std::move(fused));
  if (map_saver_ != nullptr && out.own_frame) map_saver_->sessionNotFound();
  if (map_saver_ != nullptr && !out.frame.source_interrupted) {
    if (const auto pose = mapPoseOf(out)) {
      map_saver_->addPose(out.frame.timestamp_ns, *pose);
    }
    map_saver_->checkpoint(static_cast<std::int64_t>(out.frame.index));
  }
  return out;
}

std::vector<planes::PatchEvent> RunStages::finishStream() {
  // The frames are over: what the end builds is freed for good, so it is handed back promptly.
  if (freed_memory_return_.every_s > 0.0) core::returnFreedMemorySooner();
  if (loop_closer_ == nullptr) return planes_.finishStream();
  const auto start = std::chrono::steady_clock::now();
  loop_closer_->finish();
  loop_wait_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  forgetCoveredKeyframes();
  if (surface_ != nullptr) surface_->start();
  return planes_.finishStream(loop_closer_->correction());
}

std::vector<planes::PatchSnapshot> RunStages::snapshots(const std::vector<int>& ids) const {
  return planes_.snapshots(ids);
}

void RunStages::frameDone(const FusedFrame& fused) {
  sink_.process(fused);
  returnFreedMemoryAboveBudget();
  if (listener_ == nullptr || fused.frame.source_interrupted) return;
  if (const std::optional<core::Isometry> pose = mapPoseOf(fused)) {
    listener_->onPose(fused.frame.timestamp_ns, *pose);
  }
}

void RunStages::returnFreedMemoryAboveBudget() {
  // What a return leaves above the heap in use (code, libraries, thread stacks) was 90 to 135
  // MB on the loop ring: below this much more there is little to give back, and a heap in use
  // above the budget is not trimmed every second for nothing.
  constexpr double kWorthReturningMb = 150.0;
  const double budget_mb = freed_memory_return_.above_mb;
  if (budget_mb <= 0.0) return;
  const double resident_mb = core::residentMb();
  if (resident_mb <= budget_mb) return;
  const SteadyTime now = std::chrono::steady_clock::now();
  if (std::chrono::duration<double>(now - over_budget_returned_at_).count() < 1.0) return;
  over_budget_returned_at_ = now;
  if (resident_mb - core::heapInUseMb() < kWorthReturningMb) return;  // about 1 ms
  core::returnFreedMemory();
  over_budget_returned_at_ = std::chrono::steady_clock::now();
  spdlog::debug("resident memory above {:.0f} MB: returned freed memory in {:.1f} ms", budget_mb,
                std::chrono::duration<double, std::milli>(over_budget_returned_at_ - now).count());
}

void RunStages::returnFreedMemory() {
  if (freed_memory_return_.every_s <= 0.0) return;
  const SteadyTime now = std::chrono::steady_clock::now();
  if (std::chrono::duration<double>(now - freed_memory_returned_at_).count() <
      freed_memory_return_.every_s) {
    return;
  }
  core::returnFreedMemory();
  freed_memory_returned_at_ = std::chrono::steady_clock::now();
  spdlog::debug("returned freed memory to the kernel in {:.1f} ms",
                std::chrono::duration<double, std::milli>(freed_memory_returned_at_ - now).count());
}

std::optional<CommitMessage> RunStages::commit(DescribedPatch described) {
  if (described.retired) {
    commit_.retire(*described.retired);
    if (listener_ != nullptr) listener_->onPatchRetired(*described.retired);
    return std::nullopt;
  }
  CommitMessage message;
  message.batch = described.batchInfo();
  std::optional<texture::PatchBitmap> bitmap = described.bitmap;
  const planes::Patch::Frame plane = described.plane;
  message.record = commit_.process(std::move(described));
  if (listener_ != nullptr && bitmap && message.record.instance) {
    listener_->onPatch({bitmap->id, bitmap->version, message.record.instance->reused, plane,
                        &bitmap->grid, &bitmap->image});
  }
  bitmaps_.keep(std::move(bitmap));
  returnFreedMemory();
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
