#include "tessera/drivers/synthetic/sensor_model.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <fmt/format.h>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"

namespace tessera::drivers::synthetic {

SensorProfile SensorProfile::named(const std::string& name) {
  SensorProfile p;
  p.name = name;
  p.intrinsics.width = 640, p.intrinsics.height = 480;
  p.intrinsics.fx = 525.0, p.intrinsics.fy = 525.0, p.intrinsics.cx = 319.5,
  p.intrinsics.cy = 239.5;
  if (name == "kinect_v1") return p;
  if (name == "ideal") {
    p.disparity_quantisation = false;
    p.noise_a_m = p.noise_b = 0.0;
    p.grazing_start_deg = p.grazing_full_deg = 90.0;
    p.edge_dropout = 0.0;
    p.colour_noise_sigma = p.colour_blur_sigma_px = 0.0;
    return p;
  }
  if (name == "kinect_v2") {
    // Time of flight: no disparity steps, a millimetre-level noise floor, flying pixels at
    // depth edges; depth at 512x424 with libfreenect2-style registered colour.
    p.intrinsics.width = 512, p.intrinsics.height = 424;
    p.intrinsics.fx = 365.0, p.intrinsics.fy = 365.0, p.intrinsics.cx = 255.5,
    p.intrinsics.cy = 211.5;
    p.disparity_quantisation = false;
    p.noise_a_m = 0.0015, p.noise_b = 0.0006, p.noise_c_m = 0.5;
    p.grazing_start_deg = 75.0, p.grazing_full_deg = 88.0;
    p.edge_dropout = 0.9;
    return p;
  }
  throw core::ConfigError(
      fmt::format("unknown sensor profile '{}' (known: {})", name, knownNames()));
}

std::string SensorProfile::knownNames() { return "kinect_v1, kinect_v2, ideal"; }

double depthNoiseSigma(const SensorProfile& profile, double z_m) {
  const double dz = z_m - profile.noise_c_m;
  return profile.noise_a_m + profile.noise_b * dz * dz;
}

void applySensor(const SensorProfile& profile, const CleanView& view, std::uint64_t seed,
                 cv::Mat& depth_mm, cv::Mat& rgb) {
  const int rows = view.depth_m.rows, cols = view.depth_m.cols;
  depth_mm.create(rows, cols, CV_16UC1);
  const double bf = profile.baseline_m * profile.disparity_focal_px;
  const double cos_start = std::cos(profile.grazing_start_deg * M_PI / 180.0);
  const double cos_full = std::cos(profile.grazing_full_deg * M_PI / 180.0);

  cv::parallel_for_(cv::Range(0, rows), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
      // One generator per row, seeded from (seed, row): the same result for any thread count.
      std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ULL + static_cast<std::uint64_t>(v));
      std::normal_distribution<double> gauss(0.0, 1.0);
      std::uniform_real_distribution<double> uniform(0.0, 1.0);
      const auto* z_row = view.depth_m.ptr<double>(v);
      const auto* cos_row = view.cos_incidence.ptr<double>(v);
      auto* out = depth_mm.ptr<std::uint16_t>(v);
      for (int u = 0; u < cols; ++u) {
        // Draw every random number for every pixel so the stream does not depend on content.
        const double noise = gauss(rng), drop_grazing = uniform(rng), drop_edge = uniform(rng);
        double z = z_row[u];
        out[u] = 0;
        if (z < profile.min_depth_m || z > profile.max_depth_m) continue;
        const double c = cos_row[u];
        if (c < cos_start) {
          const double p = cos_start > cos_full ? (cos_start - c) / (cos_start - cos_full) : 1.0;
          if (drop_grazing < p) continue;
        }
        if (profile.edge_dropout > 0.0) {
          bool edge = false;
          for (const auto& [du, dv] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
            const int nu = u + du, nv = v + dv;
            if (nu < 0 || nv < 0 || nu >= cols || nv >= rows) continue;
            const double zn = view.depth_m.at<double>(nv, nu);
            edge |= zn <= 0.0 || std::abs(zn - z) > profile.edge_jump_fraction * z;
          }
          if (edge && drop_edge < profile.edge_dropout) continue;
        }
        z += depthNoiseSigma(profile, z) * noise;
        if (profile.disparity_quantisation) {
          const double disparity = bf / z;
          z = bf / (std::round(disparity / profile.disparity_step_px) * profile.disparity_step_px);
        }
        out[u] = static_cast<std::uint16_t>(std::clamp(std::lround(z * 1000.0), 0L, 65535L));
      }
    }
  });

  cv::Mat colour = view.colour.clone();
  if (profile.colour_blur_sigma_px > 0.0) {
    cv::GaussianBlur(colour, colour, cv::Size(0, 0), profile.colour_blur_sigma_px);
  }
  if (profile.colour_noise_sigma > 0.0) {
    cv::Mat noise(colour.size(), CV_32FC3);
    cv::RNG rng(seed ^ 0xC0FFEEULL);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, profile.colour_noise_sigma);
    colour += noise;
  }
  colour.convertTo(rgb, CV_8UC3);  // rounds and saturates to 0..255
}

}  // namespace tessera::drivers::synthetic
