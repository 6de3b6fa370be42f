#include "tessera/eval/view_evaluation.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"
#include "tessera/core/registration.h"

namespace tessera::eval {

namespace {

constexpr std::int64_t kMaxPoseGapNs = 1'000'000;  // a pose belongs to a frame within 1 ms
// Colour times are interpolated between the frames' poses up to this far apart (a few frames).
constexpr std::int64_t kMaxInterpolationGapNs = 100'000'000;

std::optional<core::Isometry> poseAt(const core::Trajectory& poses, std::int64_t timestamp_ns) {
  auto it = poses.lower_bound(timestamp_ns - kMaxPoseGapNs);
  if (it == poses.end() || it->first > timestamp_ns + kMaxPoseGapNs) return std::nullopt;
  return it->second;
}

// The pose `frame` is rendered at: at its colour image's time when asked and known.
std::optional<core::Isometry> viewPose(const core::Trajectory& poses, const core::Frame& frame,
                                       bool colour_time) {
  if (colour_time && frame.colour_timestamp_ns) {
    return core::poseAt(poses, *frame.colour_timestamp_ns, kMaxInterpolationGapNs);
  }
  return poseAt(poses, frame.timestamp_ns);
}

// Pixels where the first model drew something that the captured depth confirms.
cv::Mat confirmedCoverage(const ViewImage& view, const core::Frame& frame,
                          const ViewEvaluationOptions& options) {
  cv::Mat mask = cv::Mat::zeros(view.depth.size(), CV_8UC1);
  for (int y = 0; y < mask.rows; ++y) {
    const auto* rendered = view.depth.ptr<float>(y);
    const auto* captured = frame.depth_mm.ptr<std::uint16_t>(y);
    auto* out = mask.ptr<std::uint8_t>(y);
    for (int x = 0; x < mask.cols; ++x) {
      if (rendered[x] <= 0.0F || captured[x] == 0) continue;
      const double z = rendered[x];
      const double tolerance = options.depth_tolerance_m + options.depth_tolerance_per_m2 * z * z;
      if (std::abs(captured[x] / 1000.0 - z) <= tolerance) out[x] = 255;
    }
  }
  if (const int margin = options.edge_margin_px; margin > 0) {
    cv::erode(mask, mask,
              cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * margin + 1, 2 * margin + 1)));
  }
  return mask;
}

// render | captured | |difference| (x4), with the pixels outside the mask dimmed.
void saveComparison(const cv::Mat& rendered, const cv::Mat& captured, const cv::Mat& mask,
                    const std::filesystem::path& path) {
  cv::Mat difference;
  cv::absdiff(rendered, captured, difference);
  difference *= 4.0;
  cv::Mat outside;
  cv::bitwise_not(mask, outside);
  std::vector<cv::Mat> panels = {rendered.clone(), captured.clone(), difference};
  for (cv::Mat& panel : panels) {
    cv::Mat dimmed = panel / 4;
    dimmed.copyTo(panel, outside);
  }
  cv::Mat row, bgr;
  cv::hconcat(panels, row);
  cv::cvtColor(row, bgr, cv::COLOR_RGB2BGR);
  if (!cv::imwrite(path.string(), bgr)) {
    throw core::Error(fmt::format("{}: could not be written", path.string()));
  }
}

// Adds each compared pixel's squared error, per model, to the surface models[0] drew there.
void addSurfaceErrors(const std::vector<ViewImage>& renders, const cv::Mat& captured,
                      const cv::Mat& mask, std::vector<SurfaceError>& surfaces) {
  for (int y = 0; y < mask.rows; ++y) {
    const auto* compared = mask.ptr<std::uint8_t>(y);
    const auto* surface = renders[0].surface.ptr<int>(y);
    const auto* truth = captured.ptr<cv::Vec3b>(y);
    for (int x = 0; x < mask.cols; ++x) {
      if (compared[x] == 0 || surface[x] < 0 ||
          static_cast<std::size_t>(surface[x]) >= surfaces.size()) {
        continue;
      }
      SurfaceError& into = surfaces[static_cast<std::size_t>(surface[x])];
      ++into.pixels;
      for (std::size_t m = 0; m < renders.size(); ++m) {
        const cv::Vec3b& drawn = renders[m].rgb.at<cv::Vec3b>(y, x);
        for (int ch = 0; ch < 3; ++ch) {
          const double d = static_cast<double>(drawn[ch]) - static_cast<double>(truth[x][ch]);
          into.squared_error[m] += d * d;
        }
      }
    }
  }
}

// Spreads `wanted` views evenly over `total` candidates: every stride-th is taken.
std::size_t strideFor(std::size_t total, int wanted) {
  if (wanted <= 0) return 1;
  const auto n = static_cast<std::size_t>(wanted);
  return std::max<std::size_t>(1, (total + n - 1) / n);
}

}  // namespace

std::optional<double> SurfaceError::psnr(std::size_t model) const {
  if (pixels == 0) return std::nullopt;
  const double mse = squared_error.at(model) / (3.0 * static_cast<double>(pixels));
  return mse > 0.0 ? 10.0 * std::log10(255.0 * 255.0 / mse) : 99.0;
}

std::optional<double> ViewEvaluation::mean(std::size_t model, bool held_out,
                                           double ImageSimilarity::*figure) const {
  double sum = 0.0;
  std::size_t n = 0;
  for (const ViewScore& view : views) {
    if (view.held_out != held_out) continue;
    sum += view.similarity.at(model).*figure;
    ++n;
  }
  if (n == 0) return std::nullopt;
  return sum / static_cast<double>(n);
}

std::size_t ViewEvaluation::pixels(bool held_out) const {
  std::size_t total = 0;
  for (const ViewScore& view : views) {
    if (view.held_out == held_out) total += view.pixels;
  }
  return total;
}

std::string ViewEvaluation::poseTime() const {
  const auto at_colour = std::count_if(views.begin(), views.end(),
                                       [](const ViewScore& v) { return v.at_colour_time; });
  if (at_colour == 0) return "depth";
  return static_cast<std::size_t>(at_colour) == views.size() ? "colour" : "mixed";
}

std::size_t ViewEvaluation::viewCount(bool held_out) const {
  return static_cast<std::size_t>(std::count_if(
      views.begin(), views.end(), [&](const ViewScore& v) { return v.held_out == held_out; }));
}

ViewEvaluation evaluateViews(const std::vector<ViewModel>& models, core::FrameSource& frames,
                             const core::Trajectory& poses, const ViewEvaluationOptions& options) {
  if (models.empty()) throw core::Error("view evaluation: no model to render");
  ViewEvaluation evaluation;
  for (const ViewModel& model : models) evaluation.models.push_back(model.name);
  for (const std::string& name : models[0].mesh->surfaces) {
    evaluation.surfaces.push_back({name, 0, std::vector<double>(models.size(), 0.0)});
  }
  if (!options.save_dir.empty()) {
    std::error_code error;
    std::filesystem::create_directories(options.save_dir, error);
    if (error) {
      throw core::Error(
          fmt::format("{}: cannot be created: {}", options.save_dir.string(), error.message()));
    }
  }

  // Held-out frames are every holdout_every-th, the rest training frames; each kind is spread
  // evenly over the recording when its length is known, else every frame is scored.
  std::size_t train_stride = 1, held_out_stride = 1;
  if (const std::optional<std::size_t> total = frames.frameCount()) {
    const std::size_t held_out =
        options.holdout_every > 1 ? *total / static_cast<std::size_t>(options.holdout_every) : 0;
    train_stride = strideFor(*total - held_out, options.max_views);
    held_out_stride = strideFor(held_out, options.max_views);
  }
  std::size_t seen[2] = {0, 0};  // training, held-out frames met so far
  bool said_no_colour_time = false;
  int saved = 0;
  const int save_every = std::max(1, options.max_views / std::max(1, options.save_views));

  for (;;) {
    core::ReadResult result = frames.read();
    if (result.status == core::ReadStatus::kEndOfData) {
      if (!result.problem.empty()) {
        spdlog::warn("{}: {}; views scored so far are kept", frames.name(), result.problem);
      }
      break;
    }
    if (result.status != core::ReadStatus::kFrame) continue;
    core::Frame& frame = result.frame;
    const bool held_out = core::isHeldOut(frame.index, options.holdout_every);
    const std::size_t position = seen[held_out ? 1 : 0]++;
    if (position % (held_out ? held_out_stride : train_stride) != 0) continue;
    if (options.colour_time && !frame.colour_timestamp_ns && !said_no_colour_time) {
      spdlog::info("{}: no colour time stamps; views are rendered at the depth image's pose",
                   frames.name());
      said_no_colour_time = true;
    }
    std::vector<core::Isometry> T_W_C;  // per model
    for (const ViewModel& model : models) {
      const auto pose =
          viewPose(model.poses != nullptr ? *model.poses : poses, frame, options.colour_time);
      if (!pose) break;
      T_W_C.push_back(*pose);
    }
    if (T_W_C.size() < models.size()) continue;
    if (frame.colour_camera) frame = core::withRegisteredColour(std::move(frame));
    if (frame.rgb.empty() || frame.depth_mm.empty()) continue;
    // Renders are the intrinsics' size; a frame of another size cannot be compared with them.
    const cv::Size size(frame.intrinsics.width, frame.intrinsics.height);
    if (frame.rgb.size() != size || frame.depth_mm.size() != size) {
      spdlog::warn("{}: frame {} is {}x{}, not the intrinsics' {}x{}: not scored", frames.name(),
                   frame.index, frame.rgb.cols, frame.rgb.rows, size.width, size.height);
      continue;
    }

    std::vector<ViewImage> renders;
    for (std::size_t m = 0; m < models.size(); ++m) {
      renders.push_back(renderView(*models[m].mesh, frame.intrinsics, T_W_C[m]));
    }
    cv::Mat mask = confirmedCoverage(renders[0], frame, options);
    for (std::size_t m = 1; m < renders.size(); ++m) mask &= renders[m].depth > 0.0F;
    ViewScore score;
    score.index = frame.index;
    score.timestamp_ns = frame.timestamp_ns;
    score.held_out = held_out;
    score.at_colour_time = options.colour_time && frame.colour_timestamp_ns.has_value();
    score.pixels = static_cast<std::size_t>(cv::countNonZero(mask));
    if (score.pixels < options.min_pixels) continue;
    for (const ViewImage& render : renders) {
      score.similarity.push_back(*compareImages(render.rgb, frame.rgb, mask));
    }
    if (!held_out) addSurfaceErrors(renders, frame.rgb, mask, evaluation.surfaces);
    const std::size_t scored = evaluation.views.size();
    if (!options.save_dir.empty() && saved < options.save_views &&
        scored % static_cast<std::size_t>(save_every) == 0) {
      for (std::size_t m = 0; m < models.size(); ++m) {
        saveComparison(renders[m].rgb, frame.rgb, mask,
                       options.save_dir / fmt::format("view_{:06d}{}_{}.png", frame.index,
                                                      held_out ? "_heldout" : "", models[m].name));
      }
      ++saved;
    }
    spdlog::debug("view {}{}: {} pixels, {:.2f} dB, SSIM {:.3f}, detail {:.3f} ({})", frame.index,
                  held_out ? " (held out)" : "", score.pixels, score.similarity[0].psnr_db,
                  score.similarity[0].ssim, score.similarity[0].detail, models[0].name);
    evaluation.views.push_back(std::move(score));
  }
  return evaluation;
}

namespace {

struct NamedFigure {
  const char* name;
  double ImageSimilarity::*figure;
  bool held_out;  // also over the held-out views
};
constexpr NamedFigure kFigures[] = {
    {"psnr", &ImageSimilarity::psnr_db, true},
    {"ssim", &ImageSimilarity::ssim, true},
    {"detail", &ImageSimilarity::detail, true},
    {"detail_correlation", &ImageSimilarity::detail_correlation, false},
    {"detail_energy_ratio", &ImageSimilarity::detail_energy_ratio, false}};

constexpr std::size_t kWorstSurfaces = 10;

// The surfaces whose error exceeds the baseline's most over the training views (the model's
// own error without a baseline): where a map loses, by how much, and its share of what the
// losing surfaces lose together (the map may still win overall).
nlohmann::json worstSurfaces(const ViewEvaluation& evaluation) {
  const std::size_t reference = evaluation.models.size() > 1 ? 1 : 0;
  const auto excess = [&](const SurfaceError& s) {
    return s.squared_error[0] - (reference > 0 ? s.squared_error[reference] : 0.0);
  };
  std::vector<const SurfaceError*> seen;
  double total_excess = 0.0;
  for (const SurfaceError& surface : evaluation.surfaces) {
    if (surface.pixels == 0) continue;
    seen.push_back(&surface);
    total_excess += std::max(0.0, excess(surface));  // what the losing surfaces lose
  }
  std::sort(seen.begin(), seen.end(),
            [&](const SurfaceError* a, const SurfaceError* b) { return excess(*a) > excess(*b); });
  nlohmann::json worst = nlohmann::json::array();
  for (std::size_t i = 0; i < std::min(kWorstSurfaces, seen.size()); ++i) {
    const SurfaceError& s = *seen[i];
    nlohmann::json entry = {{"surface", s.name}, {"pixels", s.pixels}, {"psnr_db", *s.psnr(0)}};
    if (reference > 0) {
      entry["baseline_psnr_db"] = *s.psnr(reference);
      entry["share_of_loss"] = total_excess > 0.0 ? excess(s) / total_excess : 0.0;
    }
    worst.push_back(std::move(entry));
  }
  return worst;
}

}  // namespace

nlohmann::json viewFigures(const ViewEvaluation& evaluation) {
  const auto figure = [](std::optional<double> value) {
    return value ? nlohmann::json(*value) : nlohmann::json(nullptr);
  };
  const bool has_baseline = evaluation.models.size() > 1;
  nlohmann::json figures = {{"view_pixels", evaluation.pixels(false)},
                            {"view_pixels_holdout", evaluation.pixels(true)},
                            {"view_frames", evaluation.viewCount(false)},
                            {"view_frames_holdout", evaluation.viewCount(true)},
                            {"view_pose_time", evaluation.poseTime()}};
  for (const NamedFigure& f : kFigures) {
    const std::string key = fmt::format("view_{}", f.name);
    for (const bool held_out : {false, true}) {
      if (held_out && !f.held_out) continue;
      const std::string suffix = held_out ? "_holdout_mean" : "_mean";
      figures[key + suffix] = figure(evaluation.mean(0, held_out, f.figure));
      figures[key + "_baseline" + suffix] =
          has_baseline ? figure(evaluation.mean(1, held_out, f.figure)) : nlohmann::json(nullptr);
    }
  }
  figures["view_surfaces_worst"] = worstSurfaces(evaluation);
  return figures;
}

}  // namespace tessera::eval
