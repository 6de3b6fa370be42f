#pragma once
// Deterministic hash noise for procedural textures: the same inputs give the same value on
// every machine and thread.
#include <cmath>
#include <cstdint>

namespace tessera::drivers::synthetic::noise {

// A well-mixed 32-bit hash of two integers and a seed (integer avalanche, after Wang/Jenkins).
inline std::uint32_t hash(std::int64_t x, std::int64_t y, std::uint32_t seed) {
  std::uint64_t h =
      static_cast<std::uint64_t>(x) * 0x9E3779B97F4A7C15ULL ^
      (static_cast<std::uint64_t>(y) + 0x632BE59BD9B4E019ULL) * 0xBF58476D1CE4E5B9ULL ^
      static_cast<std::uint64_t>(seed) * 0x94D049BB133111EBULL;
  h ^= h >> 31;
  h *= 0xD6E8FEB86659FD93ULL;
  h ^= h >> 32;
  return static_cast<std::uint32_t>(h);
}

// Uniform in [0, 1).
inline double unit(std::int64_t x, std::int64_t y, std::uint32_t seed) {
  return static_cast<double>(hash(x, y, seed)) / 4294967296.0;
}

// Smooth value noise in [0, 1) with unit cell size: hashed lattice values blended with a
// smoothstep.
inline double value(double x, double y, std::uint32_t seed) {
  const double fx = std::floor(x), fy = std::floor(y);
  const auto ix = static_cast<std::int64_t>(fx), iy = static_cast<std::int64_t>(fy);
  const double tx = x - fx, ty = y - fy;
  const double sx = tx * tx * (3 - 2 * tx), sy = ty * ty * (3 - 2 * ty);
  const double a = unit(ix, iy, seed), b = unit(ix + 1, iy, seed);
  const double c = unit(ix, iy + 1, seed), d = unit(ix + 1, iy + 1, seed);
  return (a + (b - a) * sx) * (1 - sy) + (c + (d - c) * sx) * sy;
}

// Sum of `octaves` value-noise layers, each twice the frequency and half the amplitude;
// result in [0, 1).
inline double fractal(double x, double y, std::uint32_t seed, int octaves) {
  double sum = 0.0, amplitude = 0.5, norm = 0.0;
  for (int o = 0; o < octaves; ++o) {
    sum += amplitude * value(x, y, seed + static_cast<std::uint32_t>(o) * 101u);
    norm += amplitude;
    x *= 2.0;
    y *= 2.0;
    amplitude *= 0.5;
  }
  return sum / norm;
}

}  // namespace tessera::drivers::synthetic::noise
