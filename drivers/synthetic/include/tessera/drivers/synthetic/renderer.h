#pragma once
// Ray casting of a synthetic scene, and the FrameSource that renders one frame per read.
#include <cstddef>
#include <filesystem>

#include "tessera/core/frame_source.h"
#include "tessera/drivers/synthetic/scene.h"

namespace tessera::drivers::synthetic {

// Perfect depth, colour, incidence and surface ids seen from T_W_C. Colour averages
// `supersample` x `supersample` rays per pixel; depth is that of the pixel's centre ray.
// Thread-safe (reads the scene only); parallel over rows.
CleanView renderClean(const Scene& scene, const core::Intrinsics& k, const core::Isometry& T_W_C,
                      int supersample = 2);

// Renders frame i of a scene through its sensor model: deterministic for the scene's seed.
// Not thread-safe (one reader).
class SyntheticSource : public core::FrameSource {
 public:
  // Throws core::ConfigError for a bad scene file.
  explicit SyntheticSource(const std::filesystem::path& scene_file);

  core::ReadResult read() override;
  std::string name() const override { return name_; }
  std::optional<std::size_t> frameCount() const override {
    return static_cast<std::size_t>(scene_.frames);
  }
  const Scene& scene() const { return scene_; }
  // Renders with another sensor profile than the scene file names (its colour registration
  // setting is kept).
  void useSensor(const SensorProfile& sensor) {
    const bool registered = scene_.sensor.colour_registered;
    scene_.sensor = sensor;
    scene_.sensor.colour_registered = registered;
  }

 private:
  std::string name_;
  Scene scene_;
  int next_ = 0;
};

}  // namespace tessera::drivers::synthetic
