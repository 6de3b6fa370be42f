#pragma once
// OUT/mesh.ply's surface. When loop closure moved keyframes, the TSDF is fused again at the
// corrected poses from the frames kept for it (fusion::ReintegrationLog). That starts on a
// thread of its own once loop closure's last optimisation is known, at the end of the stream,
// so that it runs beside the texturing of the patches left instead of after it.
#include <future>
#include <optional>

#include "tessera/fusion/tsdf_map.h"
#include "tessera/loop/loop_closer.h"
#include "tessera/pipeline/stage_figures.h"
#include "tessera/pipeline/stages.h"

namespace tessera::pipeline::internal {

class CorrectedSurface {
 public:
  // `loop_closer`: null without loop closure. The thread's nice value is raised by `nice`, as
  // the texturing threads' are, so that the two share the cores.
  CorrectedSurface(IntegrationStage& integration, const loop::LoopCloser* loop_closer, int nice)
      : integration_(integration), loop_closer_(loop_closer), nice_(nice) {}
  CorrectedSurface(const CorrectedSurface&) = delete;
  CorrectedSurface& operator=(const CorrectedSurface&) = delete;

  // Loop closure has finished: fuses the TSDF again if its optimisations moved keyframes and
  // the frames were kept. The integration stage is the thread's until wait().
  void start();
  // Waits for start()'s fusion, if any.
  void wait();
  // The surface to export, once: the corrected one (its figures added to `loops`), else the
  // TSDF's as fused (also when the fusion failed: a warning says why).
  fusion::SurfaceMesh take(LoopFigures& loops);

 private:
  struct Corrected {
    std::optional<fusion::SurfaceMesh> mesh;  // none: the TSDF as fused, not yet meshed
    bool fused_again = false;                 // false: `mesh` is the TSDF as fused
    double seconds = 0.0;
  };
  Corrected fuseAgain() const;

  IntegrationStage& integration_;
  const loop::LoopCloser* loop_closer_;
  const int nice_;
  std::future<Corrected> fusing_;
  std::optional<Corrected> corrected_;
};

}  // namespace tessera::pipeline::internal
