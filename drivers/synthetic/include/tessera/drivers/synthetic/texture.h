#pragma once
// Textures of synthetic scenes: a colour for every point of the texture plane, in metres.
// Procedural generators are deterministic for their seed; periodic ones know their exact
// period lattice, which the ground truth records.
#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

#include "tessera/core/config.h"

namespace tessera::drivers::synthetic {

// Two period vectors (metres, texture coordinates): colour(p + i a + j b) == colour(p).
using Lattice = std::array<Eigen::Vector2d, 2>;

// Thread-safe for concurrent colour() calls (immutable after construction).
class Texture {
 public:
  virtual ~Texture() = default;
  // RGB in [0, 255] at texture coordinates (s, t) in metres.
  virtual cv::Vec3f colour(double s, double t) const = 0;
  // The smallest exact period lattice, for periodic textures.
  virtual std::optional<Lattice> lattice() const { return std::nullopt; }
  // Size in metres for finite textures (posters, photos), whose colour outside
  // [0, width] x [0, height] is the edge's.
  virtual std::optional<Eigen::Vector2d> extent() const { return std::nullopt; }
  const std::string& generator() const { return generator_; }

 protected:
  explicit Texture(std::string generator) : generator_(std::move(generator)) {}

 private:
  std::string generator_;
};

// Builds a texture from its scene-file entry (`generator:` and that generator's keys).
// Relative image paths resolve against `scene_dir`. Throws core::ConfigError naming the file
// and the entry, listing the known generators when the name is unknown.
std::unique_ptr<Texture> makeTexture(const core::ConfigSection& entry,
                                     const std::string& scene_dir);

// Names of the generators makeTexture knows.
std::vector<std::string> textureGenerators();

}  // namespace tessera::drivers::synthetic
