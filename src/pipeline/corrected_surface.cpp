#include "internal/corrected_surface.h"

#include <chrono>
#include <exception>
#include <utility>

#include <spdlog/spdlog.h>

#include "internal/background_workers.h"
#include "tessera/core/error.h"
#include "tessera/core/memory.h"

namespace tessera::pipeline::internal {

void CorrectedSurface::start() {
  if (fusing_.valid() || corrected_) return;
  const fusion::ReintegrationLog* log = integration_.reintegrationLog();
  if (loop_closer_ == nullptr || log == nullptr || log->size() == 0 ||
      loop_closer_->graph().stats().optimisations == 0) {
    return;
  }
  fusing_ = std::async(std::launch::async, [this] {
    lowerOwnPriority(nice_);
    const auto begin = std::chrono::steady_clock::now();
    Corrected corrected = fuseAgain();
    corrected.seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
    return corrected;
  });
}

void CorrectedSurface::wait() {
  if (fusing_.valid()) corrected_ = fusing_.get();
}

CorrectedSurface::Corrected CorrectedSurface::fuseAgain() const {
  const fusion::ReintegrationLog& log = *integration_.reintegrationLog();
  if (!log.usable()) {
    spdlog::warn("mesh.ply stays at the tracked poses: {}", log.error());
    return {};
  }
  const loop::MapCorrection correction = loop_closer_->graph().correction();
  // The surface at the tracked poses stays as the fallback; its volume (the run's largest
  // store) is freed before the second volume is fused.
  fusion::SurfaceMesh tracked = integration_.takeSurface();
  // The volume's blocks were freed on the threads that fused them; this thread's allocations
  // would not reuse them, so they go back to the kernel before the second volume grows.
  core::returnFreedMemory();
  try {
    return {log.rebuild(integration_.map().config(),
                        [&correction](std::int64_t anchor_ns) -> std::optional<core::Isometry> {
                          if (!correction.inMap(anchor_ns)) return std::nullopt;  // never joined
                          return correction.at(anchor_ns);
                        }),
            true};
  } catch (const std::exception& e) {  // a kept frame unreadable, or memory short
    spdlog::warn("mesh.ply stays at the tracked poses: {}", e.what());
    return {std::move(tracked), false};
  }
}

fusion::SurfaceMesh CorrectedSurface::take(LoopFigures& loops) {
  wait();
  if (const fusion::ReintegrationLog* log = integration_.reintegrationLog()) {
    loops.tsdf_frames_kept = log->size();
    loops.tsdf_frames_kept_bytes = log->diskBytes();
  }
  std::optional<Corrected> corrected = std::exchange(corrected_, std::nullopt);
  if (!corrected || !corrected->mesh) return integration_.takeSurface();
  if (!corrected->fused_again) return std::move(*corrected->mesh);
  loops.tsdf_corrected = true;
  loops.tsdf_correction_s = corrected->seconds;
  spdlog::info("TSDF fused again at the corrected poses from {} keyframes in {:.1f} s",
               loops.tsdf_frames_kept, loops.tsdf_correction_s);
  return std::move(*corrected->mesh);
}

}  // namespace tessera::pipeline::internal
