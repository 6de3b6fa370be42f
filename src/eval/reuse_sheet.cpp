#include "tessera/eval/reuse_sheet.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"
#include "tessera/match/fidelity.h"

namespace tessera::eval {

namespace {

namespace fs = std::filesystem;

// An RGBA PNG as RGB (CV_8UC3) and its alpha (CV_8UC1).
void readRgba(const fs::path& path, cv::Mat& rgb, cv::Mat& alpha) {
  const cv::Mat bgra = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  if (bgra.empty() || bgra.type() != CV_8UC4) {
    throw core::Error(fmt::format("{}: missing or not an RGBA PNG", path.string()));
  }
  cv::cvtColor(bgra, rgb, cv::COLOR_BGRA2RGB);
  cv::extractChannel(bgra, alpha, 3);
}

nlohmann::json readPatchesJson(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw core::Error(fmt::format("{}: cannot open", path.string()));
  nlohmann::json json = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (json.is_discarded() || !json.contains("patches") || !json["patches"].is_array()) {
    throw core::Error(fmt::format("{}: not a patches.json (no \"patches\" list)", path.string()));
  }
  return json;
}

// PSNR of `a` against `b` (CV_8UC3) over `mask`; nothing when the mask is empty.
std::optional<double> psnrOver(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask) {
  double squared = 0.0;
  std::size_t values = 0;
  for (int r = 0; r < a.rows; ++r) {
    for (int c = 0; c < a.cols; ++c) {
      if (mask.at<std::uint8_t>(r, c) == 0) continue;
      for (int k = 0; k < 3; ++k) {
        const double d = static_cast<double>(a.at<cv::Vec3b>(r, c)[k]) - b.at<cv::Vec3b>(r, c)[k];
        squared += d * d;
      }
      values += 3;
    }
  }
  if (values == 0) return std::nullopt;
  const double mse = squared / static_cast<double>(values);
  return mse <= 0.0 ? 99.0 : std::min(99.0, 10.0 * std::log10(255.0 * 255.0 / mse));
}

// One panel of a row: `rgb` scaled to `size`, a checkerboard where `mask` is 0.
cv::Mat panel(const cv::Mat& rgb, const cv::Mat& mask, cv::Size size,
              const ReuseSheetOptions& options) {
  const bool enlarging = size.width >= rgb.cols;
  cv::Mat scaled, scaled_mask;
  cv::resize(rgb, scaled, size, 0, 0, enlarging ? cv::INTER_NEAREST : cv::INTER_AREA);
  cv::resize(mask, scaled_mask, size, 0, 0, cv::INTER_NEAREST);
  const int side = std::max(1, options.checker_px);
  for (int y = 0; y < size.height; ++y) {
    for (int x = 0; x < size.width; ++x) {
      if (scaled_mask.at<std::uint8_t>(y, x) != 0) continue;
      const std::uint8_t grey = ((x / side + y / side) % 2 == 0) ? 70 : 100;
      scaled.at<cv::Vec3b>(y, x) = cv::Vec3b(grey, grey, grey);
    }
  }
  return scaled;
}

struct SheetRow {
  std::string label;
  std::vector<cv::Mat> panels;  // CV_8UC3, already scaled
};

constexpr int kFont = cv::FONT_HERSHEY_SIMPLEX;
constexpr double kFontScale = 0.5;
constexpr int kFontThickness = 1;

SheetRow rowOf(const nlohmann::json& patch, const InstanceRender& shown, const fs::path& run_dir,
               const ReuseSheetOptions& options) {
  const auto& texture = patch.at("texture");
  const fs::path own_path = run_dir / texture.at("image").get<std::string>();
  cv::Mat own, own_mask;
  readRgba(own_path, own, own_mask);
  if (own.size() != shown.rgb.size()) {
    throw core::Error(fmt::format("{}: {}x{} texels, but patches.json gives patch {} {}x{}",
                                  own_path.string(), own.cols, own.rows, patch.at("id").get<int>(),
                                  shown.rgb.cols, shown.rgb.rows));
  }
  const cv::Mat both = own_mask & shown.covered;
  cv::Mat difference;
  cv::absdiff(own, shown.rgb, difference);
  difference.convertTo(difference, CV_8UC3, options.difference_gain);

  const double scale = std::min(static_cast<double>(options.row_height_px) / own.rows,
                                static_cast<double>(options.max_panel_width_px) / own.cols);
  const cv::Size size(std::max(1, static_cast<int>(std::lround(own.cols * scale))),
                      std::max(1, static_cast<int>(std::lround(own.rows * scale))));
  const std::optional<double> psnr = psnrOver(own, shown.rgb, both);
  SheetRow row;
  row.label = fmt::format("patch {} -> texture {}  PSNR {} dB  angle {:.1f} deg  scale {:.3f}",
                          patch.at("id").get<int>(), shown.texture_id,
                          psnr ? fmt::format("{:.1f}", *psnr) : std::string("n/a"),
                          shown.transform.angleRad() * 180.0 / M_PI, shown.transform.scale());
  row.panels = {panel(own, own_mask, size, options), panel(shown.rgb, shown.covered, size, options),
                panel(difference, both, size, options)};
  return row;
}

cv::Mat composeSheet(const std::vector<SheetRow>& rows, const ReuseSheetOptions& options) {
  const int gap = options.gap_px;
  const int pitch = options.label_height_px + options.row_height_px + gap;
  int width = 0;
  for (const SheetRow& row : rows) {
    int row_width = 0;
    for (const cv::Mat& p : row.panels) row_width += p.cols + gap;
    int baseline = 0;
    const cv::Size text = cv::getTextSize(row.label, kFont, kFontScale, kFontThickness, &baseline);
    width = std::max({width, row_width - gap, text.width});
  }
  cv::Mat sheet(gap + static_cast<int>(rows.size()) * pitch, width + 2 * gap, CV_8UC3,
                cv::Scalar::all(30));
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const int top = gap + static_cast<int>(i) * pitch;
    cv::putText(sheet, rows[i].label, cv::Point(gap, top + options.label_height_px - 9), kFont,
                kFontScale, cv::Scalar::all(235), kFontThickness, cv::LINE_AA);
    int x = gap;
    for (const cv::Mat& p : rows[i].panels) {
      const int y = top + options.label_height_px + (options.row_height_px - p.rows) / 2;
      p.copyTo(sheet(cv::Rect(x, y, p.cols, p.rows)));
      x += p.cols + gap;
    }
  }
  return sheet;
}

}  // namespace

std::optional<InstanceRender> renderInstance(const nlohmann::json& patch,
                                             const std::filesystem::path& run_dir) {
  const auto instance = patch.find("instance");
  const auto texture = patch.find("texture");
  if (instance == patch.end() || instance->is_null() || texture == patch.end() ||
      texture->is_null()) {
    return std::nullopt;
  }
  InstanceRender shown;
  shown.texture_id = instance->at("texture_id").get<std::int64_t>();
  const auto& t = instance->at("transform");
  shown.transform = {t.at(0).get<double>(), t.at(1).get<double>(), t.at(2).get<double>(),
                     t.at(3).get<double>()};
  shown.reused = instance->value("reused", false);
  shown.tiled = instance->value("tiled", false);
  if (const auto psnr = instance->find("psnr_db"); psnr != instance->end() && psnr->is_number()) {
    shown.psnr_db = psnr->get<double>();
  }
  cv::Mat rgb, alpha;
  readRgba(run_dir / instance->at("image").get<std::string>(), rgb, alpha);
  const int width = texture->at("width").get<int>(), height = texture->at("height").get<int>();
  const auto lattice = instance->find("lattice");
  match::Rendered rendered;
  if (lattice != instance->end() && lattice->is_array() && lattice->size() == 4) {
    const core::Lattice2 cell{{lattice->at(0).get<double>(), lattice->at(1).get<double>()},
                              {lattice->at(2).get<double>(), lattice->at(3).get<double>()}};
    rendered = match::renderPattern(rgb, alpha, cell, shown.transform, width, height);
  } else {
    rendered = match::renderThrough(rgb, alpha, shown.transform, width, height, shown.tiled);
  }
  // Overlays are drawn on top, each where the patch maps into its texture's rectangle.
  if (const auto overlays = instance->find("overlays");
      overlays != instance->end() && overlays->is_array()) {
    for (const auto& overlay : *overlays) {
      const auto& o = overlay.at("transform");
      const core::Similarity2 transform{o.at(0).get<double>(), o.at(1).get<double>(),
                                        o.at(2).get<double>(), o.at(3).get<double>()};
      cv::Mat overlay_rgb, overlay_alpha;
      readRgba(run_dir / overlay.at("image").get<std::string>(), overlay_rgb, overlay_alpha);
      const match::Rendered part =
          match::renderThrough(overlay_rgb, overlay_alpha, transform, width, height, false);
      part.rgb.copyTo(rendered.rgb, part.covered);
      rendered.covered |= part.covered;
    }
  }
  shown.rgb = std::move(rendered.rgb);
  shown.covered = std::move(rendered.covered);
  return shown;
}

int writeReuseSheet(const std::filesystem::path& run_dir, const ReuseSheetOptions& options) {
  const fs::path patches_path = run_dir / "patches.json";
  const fs::path sheet_path = run_dir / "reuse_sheet.png";
  if (!fs::exists(patches_path)) {
    spdlog::info("{}: not there, so no reuse sheet", patches_path.string());
    return 0;
  }
  const nlohmann::json patches = readPatchesJson(patches_path);
  std::vector<SheetRow> rows;
  try {
    for (const auto& patch : patches["patches"]) {
      const std::optional<InstanceRender> shown = renderInstance(patch, run_dir);
      if (shown && shown->reused) rows.push_back(rowOf(patch, *shown, run_dir, options));
    }
  } catch (const nlohmann::json::exception& e) {
    throw core::Error(
        fmt::format("{}: malformed patch entry: {}", patches_path.string(), e.what()));
  }
  if (rows.empty()) {
    std::error_code ignored;
    const bool removed = fs::remove(sheet_path, ignored);
    spdlog::info("{}: no reuse, so no reuse sheet{}", patches_path.string(),
                 removed ? fmt::format(" (removed the old {})", sheet_path.string()) : "");
    return 0;
  }
  cv::Mat sheet = composeSheet(rows, options);
  cv::cvtColor(sheet, sheet, cv::COLOR_RGB2BGR);
  bool written = false;
  try {
    written = cv::imwrite(sheet_path.string(), sheet);
  } catch (const cv::Exception& e) {
    throw core::Error(fmt::format("{}: cannot write: {}", sheet_path.string(), e.what()));
  }
  if (!written) throw core::Error(fmt::format("{}: cannot write", sheet_path.string()));
  return static_cast<int>(rows.size());
}

}  // namespace tessera::eval
