// The feature pose (fusion/feature_pose.h) between consecutive frames of a recording with
// ground truth: how many pairs give a pose, and how far it is from the true step. Run on a
// keyframe recording (bundlefusion_apt0_kf219: steps of 0.3 m and 12 degrees median) it says
// whether the tracker loses frames because features cannot bridge the step or because its
// checks refuse what they found. Each row relaxes one check of the default configuration.
//
//   feature_pose_bench SOURCE [--depth-scale U] [--max-frames N] [--step N]
#include <algorithm>
#include <functional>

#include <fmt/format.h>
#include <CLI/CLI.hpp>
#include <opencv2/imgproc.hpp>

#include "bench_frames.h"
#include "tessera/core/error.h"
#include "tessera/core/log.h"
#include "tessera/core/pose.h"
#include "tessera/core/registration.h"
#include "tessera/fusion/feature_pose.h"

namespace {

using tessera::core::Frame;
using tessera::fusion::FeatureFrame;
using tessera::fusion::FeaturePoseConfig;

FeatureFrame describe(const Frame& frame, const FeaturePoseConfig& config) {
  cv::Mat grey, depth_m;
  cv::cvtColor(tessera::core::registerColourToDepth(frame), grey, cv::COLOR_RGB2GRAY);
  frame.depth_mm.convertTo(depth_m, CV_32F, 1e-3);
  depth_m.setTo(std::numeric_limits<float>::quiet_NaN(), frame.depth_mm == 0);
  return tessera::fusion::describeFeatures(grey, depth_m, frame.intrinsics, config);
}

double percentile(std::vector<double> values, double p) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const auto at = static_cast<std::size_t>(p * static_cast<double>(values.size()));
  return values[std::min(values.size() - 1, at)];
}

}  // namespace

int main(int argc, char** argv) {
  namespace bench = tessera::bench;
  CLI::App app{"Feature pose between consecutive frames, against ground truth"};
  std::string source_path;
  std::size_t max_frames = 0, step = 1;
  std::optional<double> depth_units_per_m;
  app.add_option("SOURCE", source_path, "Dataset folder or .oni recording with ground truth")
      ->required();
  app.add_option("--depth-scale", depth_units_per_m, "Raw depth units per metre (folders)");
  app.add_option("--max-frames", max_frames, "Frames to load (0: all)");
  app.add_option("--step", step, "Pair frame i with frame i + step")->check(CLI::PositiveNumber);
  CLI11_PARSE(app, argc, argv);
  tessera::core::initLogging("warn");
  try {
    const std::vector<Frame> frames =
        bench::loadFrames(source_path, max_frames, true, std::nullopt, depth_units_per_m);
    struct Variant {
      std::string name;
      std::function<void(FeaturePoseConfig&)> change;
    };
    const std::vector<Variant> variants = {
        {"default", [](FeaturePoseConfig&) {}},
        {"2000 features", [](FeaturePoseConfig& c) { c.max_features = 2000; }},
        {"ratio 0.9", [](FeaturePoseConfig& c) { c.ratio_test = 0.9; }},
        {"min inliers 12", [](FeaturePoseConfig& c) { c.min_inliers = 12; }},
        {"no sigma bound",
         [](FeaturePoseConfig& c) { c.max_translation_sigma_m = c.max_rotation_sigma_deg = 1e9; }},
        {"no depth agreement", [](FeaturePoseConfig& c) { c.min_depth_agreement = 0.0; }},
        {"all of them",
         [](FeaturePoseConfig& c) {
           c.max_features = 2000;
           c.ratio_test = 0.9;
           c.min_inliers = 12;
           c.max_translation_sigma_m = c.max_rotation_sigma_deg = 1e9;
           c.min_depth_agreement = 0.0;
         }},
    };
    fmt::print("{}: {} frames, pairs i, i+{}\n", source_path, frames.size(), step);
    for (const Variant& variant : variants) {
      FeaturePoseConfig config;
      variant.change(config);
      std::vector<FeatureFrame> described;
      described.reserve(frames.size());
      for (const Frame& frame : frames) described.push_back(describe(frame, config));
      int posed = 0, wrong = 0, pairs = 0;
      std::vector<double> errors_mm, inliers;
      for (std::size_t i = 0; i + step < frames.size(); i += 1) {
        ++pairs;
        const auto pose = tessera::fusion::estimateFeaturePose(described[i], described[i + step],
                                                               frames[i].intrinsics, config);
        if (!pose) continue;
        ++posed;
        const tessera::core::Isometry truth =
            frames[i + step].T_W_C_gt->inverse() * *frames[i].T_W_C_gt;
        const tessera::core::Isometry error = truth.inverse() * pose->T_current_reference;
        const double mm = 1000.0 * error.translation().norm();
        errors_mm.push_back(mm);
        inliers.push_back(pose->inliers);
        // Wrong: further off than the tracker's relocalisation could take (10 cm, 5 degrees).
        if (mm > 100.0 || tessera::core::rotationAngleDeg(error) > 5.0) ++wrong;
      }
      fmt::print(
          "{:<20} posed {:>3} of {} pairs, {:>2} wrong (>10 cm or >5 deg); error p50 {:.1f} mm, "
          "p90 {:.1f} mm; inliers p50 {:.0f}\n",
          variant.name, posed, pairs, wrong, percentile(errors_mm, 0.5), percentile(errors_mm, 0.9),
          percentile(inliers, 0.5));
    }
  } catch (const tessera::core::Error& e) {
    fmt::print(stderr, "feature_pose_bench: {}\n", e.what());
    return 1;
  }
  return 0;
}
