#include "tessera/eval/texture_evaluation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <set>

#include <fmt/format.h>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "internal/truth_geometry.h"
#include "tessera/core/config.h"
#include "tessera/core/error.h"
#include "tessera/drivers/synthetic/texture.h"
#include "tessera/eval/reuse_sheet.h"
#include "tessera/fusion/mesh_colours.h"
#include "tessera/pattern/lattice.h"
#include "tessera/texture/bitmap_builder.h"
#include "tessera/texture/bitmap_export.h"

namespace tessera::eval {

namespace {

using drivers::synthetic::Texture;

struct TexturedPlane {
  std::string id;
  std::string texture_id;
  FramedPlane plane;
  Polygon polygon;
  const Texture* texture = nullptr;
  double rotation_rad = 0.0, scale = 1.0;
  Eigen::Vector2d texture_offset = Eigen::Vector2d::Zero();

  // Texture coordinates of plane point (u, v): (s, t) = R(rotation) (u, v) / scale + offset.
  cv::Vec3f colourAt(const Eigen::Vector2d& uv) const {
    const Eigen::Vector2d st = Eigen::Rotation2Dd(rotation_rad) * uv / scale + texture_offset;
    return texture->colour(st.x(), st.y());
  }
};

std::map<std::string, std::unique_ptr<Texture>> truthTextures(
    const nlohmann::json& truth, const std::filesystem::path& truth_dir) {
  std::map<std::string, std::unique_ptr<Texture>> textures;
  for (const auto& entry : truth.value("textures", nlohmann::json::array())) {
    const std::string id = entry.at("id").get<std::string>();
    if (!entry.contains("definition_yaml") || !entry["definition_yaml"].is_string()) {
      throw core::Error(fmt::format(
          "texture {} has no definition (ground truth written by an older tessera; render the "
          "recording again with tessera synth)",
          id));
    }
    const core::ConfigDocument definition = core::ConfigDocument::fromString(
        entry["definition_yaml"].get<std::string>(), "ground truth texture " + id);
    textures[id] = drivers::synthetic::makeTexture(definition.root(), truth_dir.string());
  }
  return textures;
}

std::vector<TexturedPlane> truthPlanes(
    const nlohmann::json& truth, const std::map<std::string, std::unique_ptr<Texture>>& textures) {
  std::vector<TexturedPlane> planes;
  for (const auto& p : truth.at("planes")) {
    TexturedPlane plane;
    plane.id = p.at("id").get<std::string>();
    plane.plane = {vec3(p.at("normal")), vec3(p.at("origin")), vec3(p.at("u_axis")),
                   vec3(p.at("v_axis")), p.at("offset_m").get<double>()};
    plane.polygon = polygonOf(p.at("polygon_uv"));
    const auto texture = textures.find(p.at("texture").get<std::string>());
    if (texture == textures.end()) {
      throw core::Error(fmt::format("plane {}: unknown texture {}", plane.id,
                                    p.at("texture").get<std::string>()));
    }
    plane.texture = texture->second.get();
    plane.texture_id = texture->first;
    const auto& mapping = p.at("texture_to_plane");
    plane.rotation_rad = mapping.at("rotation_rad").get<double>();
    plane.scale = mapping.at("scale").get<double>();
    plane.texture_offset = {mapping.at("offset_m").at(0).get<double>(),
                            mapping.at("offset_m").at(1).get<double>()};
    planes.push_back(std::move(plane));
  }
  return planes;
}

// The true plane a camera at `viewpoint` sees at X: of the planes within max_distance whose
// polygon holds X's projection, the one nearest the viewpoint (a poster before its wall).
int visiblePlane(const std::vector<TexturedPlane>& planes, const std::vector<int>& candidates,
                 const Eigen::Vector3d& X, const Eigen::Vector3d& viewpoint, double max_distance) {
  int best = -1;
  double nearest = 1e300;
  for (int i : candidates) {
    const FramedPlane& plane = planes[static_cast<std::size_t>(i)].plane;
    if (std::abs(plane.normal.dot(X) - plane.offset) > max_distance) continue;
    if (!inside(plane.uvOf(X), planes[static_cast<std::size_t>(i)].polygon)) continue;
    const double from_viewpoint = std::abs(plane.normal.dot(viewpoint) - plane.offset);
    if (from_viewpoint < nearest) nearest = from_viewpoint, best = i;
  }
  return best;
}

double psnrOf(double squared_error, std::size_t values) {
  const double mse = squared_error / static_cast<double>(std::max<std::size_t>(values, 1));
  return mse <= 0.0 ? 99.0 : 10.0 * std::log10(255.0 * 255.0 / mse);
}

// The true colour of each observed texel, averaged over its area, or nothing (plane -1) where
// the texel spans two true surfaces or none.
struct TruthImage {
  cv::Mat colour;  // CV_32FC3
  cv::Mat plane;   // CV_32SC1: index into the true planes, or -1
};

template <typename TexelToTruth>
TruthImage renderTruth(cv::Size size, const cv::Mat& state, TexelToTruth truthPoint,
                       const std::vector<TexturedPlane>& planes, const std::vector<int>& candidates,
                       const Eigen::Vector3d& viewpoint, const TextureEvaluationOptions& options) {
  TruthImage truth{cv::Mat::zeros(size, CV_32FC3), cv::Mat(size, CV_32SC1, cv::Scalar(-1))};
  const int s = std::max(1, options.supersample);
  cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& rows) {
    for (int r = rows.start; r < rows.end; ++r) {
      for (int c = 0; c < size.width; ++c) {
        if (state.at<std::uint8_t>(r, c) != static_cast<int>(texture::TexelState::kObserved)) {
          continue;
        }
        cv::Vec3f sum(0, 0, 0);
        int plane = -2;
        for (int i = 0; i < s && plane != -1; ++i) {
          for (int j = 0; j < s; ++j) {
            const Eigen::Vector3d X = truthPoint(c + (j + 0.5) / s, r + (i + 0.5) / s);
            const int here =
                visiblePlane(planes, candidates, X, viewpoint, options.max_plane_distance_m);
            if (here < 0 || (plane >= 0 && here != plane)) {
              plane = -1;
              break;
            }
            plane = here;
            const TexturedPlane& p = planes[static_cast<std::size_t>(here)];
            sum += p.colourAt(p.plane.uvOf(X));
          }
        }
        if (plane < 0) continue;
        truth.colour.at<cv::Vec3f>(r, c) = sum / static_cast<float>(s * s);
        truth.plane.at<int>(r, c) = plane;
      }
    }
  });
  return truth;
}

struct Comparison {
  std::size_t texels = 0;
  double psnr_db = 0.0;
  int main_plane = -1;  // the true plane most compared texels lie on
};

// PSNR of `image` (CV_8UC3, or CV_32FC3 with NaN where it has no colour) against the truth
// over the texels where both have a colour.
Comparison compare(const cv::Mat& image, const TruthImage& truth) {
  cv::Mat values;
  image.convertTo(values, CV_32FC3);
  double squared = 0.0;
  std::map<int, std::size_t> votes;
  Comparison result;
  for (int r = 0; r < values.rows; ++r) {
    for (int c = 0; c < values.cols; ++c) {
      const int plane = truth.plane.at<int>(r, c);
      const cv::Vec3f& got = values.at<cv::Vec3f>(r, c);
      if (plane < 0 || std::isnan(got[0])) continue;
      const cv::Vec3f d = got - truth.colour.at<cv::Vec3f>(r, c);
      squared += static_cast<double>(d.dot(d));
      ++result.texels;
      ++votes[plane];
    }
  }
  result.psnr_db = psnrOf(squared, 3 * result.texels);
  if (!votes.empty()) {
    result.main_plane =
        std::max_element(votes.begin(), votes.end(), [](const auto& a, const auto& b) {
          return a.second < b.second;
        })->first;
  }
  return result;
}

// The shift (texels) of the truth that best lines it up with the bitmap, by phase correlation
// of their grey levels where both have colour (the truth, and `rgb` where `rgb_valid` is set
// when given); zero when it exceeds max_texels.
Eigen::Vector2d registrationShift(const cv::Mat& rgb, const TruthImage& truth, double max_texels,
                                  const cv::Mat& rgb_valid = cv::Mat()) {
  cv::Mat got, want;
  cv::cvtColor(rgb, got, cv::COLOR_RGB2GRAY);
  got.convertTo(got, CV_32F);
  cv::cvtColor(truth.colour, want, cv::COLOR_RGB2GRAY);
  cv::Mat valid = truth.plane >= 0;
  if (!rgb_valid.empty()) valid &= rgb_valid;
  // Each image minus its mean where valid, zero elsewhere, so the mask's edge does not
  // dominate the correlation.
  got.setTo(cv::mean(got, valid), ~valid);
  want.setTo(cv::mean(want, valid), ~valid);
  got -= cv::mean(got, valid);
  want -= cv::mean(want, valid);
  const cv::Point2d shift = cv::phaseCorrelate(want, got);
  const Eigen::Vector2d d(-shift.x, -shift.y);  // the truth moved by -shift matches the bitmap
  return d.norm() <= max_texels ? d : Eigen::Vector2d::Zero();
}

// `rgb` (CV_8UC3) as CV_32FC3 with NaN where `covered` is 0, for compare().
cv::Mat withHoles(const cv::Mat& rgb, const cv::Mat& covered) {
  cv::Mat values;
  rgb.convertTo(values, CV_32FC3);
  values.setTo(cv::Scalar::all(std::numeric_limits<double>::quiet_NaN()), covered == 0);
  return values;
}

// The TSDF mesh's colour at each texel the truth covers (NaN where the mesh has none).
template <typename TexelToRun>
cv::Mat meshColours(const TruthImage& truth, TexelToRun runPoint,
                    const fusion::MeshColourSampler& mesh, double max_distance) {
  cv::Mat colours(truth.colour.size(), CV_32FC3, cv::Scalar::all(std::nan("")));
  cv::parallel_for_(cv::Range(0, colours.rows), [&](const cv::Range& rows) {
    for (int r = rows.start; r < rows.end; ++r) {
      for (int c = 0; c < colours.cols; ++c) {
        if (truth.plane.at<int>(r, c) < 0) continue;
        if (const auto colour = mesh.colourAt(runPoint(c + 0.5, r + 0.5), max_distance)) {
          colours.at<cv::Vec3f>(r, c) =
              cv::Vec3f(static_cast<float>(colour->x()), static_cast<float>(colour->y()),
                        static_cast<float>(colour->z()));
        }
      }
    }
  });
  return colours;
}

// Judges a reuse (docs/METRICS.md "Matching"): the texture the map shows, rendered onto the
// patch's grid, against the truth on that grid; `own_shift` is the registration shift of the
// patch's own bitmap, already in `result` with its registered PSNR. `renderTruthShifted(d)` is
// the truth on the grid moved by d texels.
template <typename RenderTruthShifted>
void judgeReuse(const InstanceRender& shown, const TruthImage& on_grid,
                const Eigen::Vector2d& own_shift, double max_shift_texels,
                RenderTruthShifted renderTruthShifted, const TextureEvaluationOptions& options,
                PatchTextureResult& result) {
  const cv::Mat values = withHoles(shown.rgb, shown.covered);
  const Comparison placed = compare(values, on_grid);
  result.reuse_texels = placed.texels;
  if (placed.texels == 0) {  // the map shows nothing where the patch saw the surface
    result.false_match = true;
    return;
  }
  result.reuse_psnr_db = placed.psnr_db;
  const Eigen::Vector2d shift =
      registrationShift(shown.rgb, on_grid, max_shift_texels, shown.covered);
  double registered = placed.psnr_db;
  if (!shift.isZero()) {
    registered = std::max(registered, compare(values, renderTruthShifted(shift)).psnr_db);
  }
  result.reuse_registered_psnr_db = registered;
  // What both shifts share is where the patch lies in the map; the rest is the transform's error.
  result.reuse_shift_texels = (shift - own_shift).norm();
  result.false_match = *result.reuse_shift_texels > options.max_reuse_shift_texels ||
                       registered < result.registered_psnr_db - options.max_reuse_psnr_drop_db;
}

// Marks the missed matches: patches that stored their own texture though an earlier-stored
// texture of the run (texture ids grow in commit order) came from the same true texture.
std::size_t markMissedMatches(std::vector<PatchTextureResult>& patches) {
  std::vector<PatchTextureResult*> stored;
  for (PatchTextureResult& p : patches) {
    if (p.texture_id && !p.reused) stored.push_back(&p);
  }
  std::sort(stored.begin(), stored.end(),
            [](const auto* a, const auto* b) { return *a->texture_id < *b->texture_id; });
  std::set<std::string> already_stored;
  std::size_t missed = 0;
  for (PatchTextureResult* p : stored) {
    p->missed_match = !already_stored.insert(p->true_texture).second;
    if (p->missed_match) ++missed;
  }
  return missed;
}

// The ideal size of the run's textures in texels of texel_m (docs/METRICS.md "Texture economy"):
// each distinct true texture of the patches once, a periodic one at its smallest exact period
// cell (as it appears on the plane: texture_to_plane's scale; the largest over the planes),
// another at the most texels one patch on it observed.
double idealPixels(const std::vector<PatchTextureResult>& patches,
                   const std::vector<int>& main_planes, const std::vector<TexturedPlane>& planes,
                   double texel_m) {
  std::map<std::string, double> ideal;  // by true texture
  for (std::size_t i = 0; i < patches.size(); ++i) {
    const TexturedPlane& plane = planes[static_cast<std::size_t>(main_planes[i])];
    double pixels = static_cast<double>(patches[i].observed_texels);
    if (const auto lattice = plane.texture->lattice()) {
      const Eigen::Vector2d& a = (*lattice)[0];
      const Eigen::Vector2d& b = (*lattice)[1];
      const double cell_m2 = std::abs(a.x() * b.y() - a.y() * b.x()) * plane.scale * plane.scale;
      pixels = cell_m2 / (texel_m * texel_m);
    }
    double& entry = ideal[plane.texture_id];
    entry = std::max(entry, pixels);
  }
  double sum = 0.0;
  for (const auto& [id, pixels] : ideal) sum += pixels;
  return sum;
}

// A pattern instance's lattice against its true texture's (METRICS.md, period error): both in
// the patch's texels. Patch texel -> texture frame is the instance's similarity S, so a frame
// vector v is S's linear part inverted applied to v; texel -> plane (u, v) -> texture (s, t) is
// affine, its linear part taken from the truth at the grid's origin.
template <typename TexelToPlane>
void judgePattern(const nlohmann::json& instance, const TexturedPlane& plane,
                  const TexelToPlane& texel_to_plane, PatchTextureResult& result) {
  const auto lattice = instance.find("lattice");
  const auto truth = plane.texture->lattice();
  if (lattice == instance.end() || !lattice->is_array() || lattice->size() != 4 || !truth) return;
  const auto& t = instance.at("transform");
  const core::Similarity2 s{t.at(0).get<double>(), t.at(1).get<double>(), 0.0, 0.0};
  const core::Similarity2 frame_to_texel = s.inverse();
  const core::Lattice2 found{
      frame_to_texel.apply({lattice->at(0).get<double>(), lattice->at(1).get<double>()}),
      frame_to_texel.apply({lattice->at(2).get<double>(), lattice->at(3).get<double>()})};
  const Eigen::Vector2d o = texel_to_plane(0.0, 0.0);
  Eigen::Matrix2d texel_to_texture;
  texel_to_texture << texel_to_plane(1.0, 0.0) - o, texel_to_plane(0.0, 1.0) - o;
  texel_to_texture =
      Eigen::Rotation2Dd(plane.rotation_rad).toRotationMatrix() * texel_to_texture / plane.scale;
  const Eigen::Matrix2d to_texels = texel_to_texture.inverse();
  const core::Lattice2 true_texels{to_texels * (*truth)[0], to_texels * (*truth)[1]};
  result.pattern_exact = pattern::sameLattice(found, true_texels, 1.0);
}

}  // namespace

TextureEvaluation evaluateTextures(
    const nlohmann::json& truth, const std::filesystem::path& truth_dir,
    const core::Trajectory& truth_poses, const nlohmann::json& patches,
    const std::filesystem::path& run_dir, const core::Isometry& T_gt_est,
    const fusion::MeshColourSampler* baseline, const TextureEvaluationOptions& options) {
  // Image textures' relative paths start at the scene file's folder, when it is still there.
  std::filesystem::path texture_dir = truth_dir;
  if (truth.contains("scene_dir") && truth["scene_dir"].is_string() &&
      std::filesystem::is_directory(truth["scene_dir"].get<std::string>())) {
    texture_dir = truth["scene_dir"].get<std::string>();
  }
  const auto textures = truthTextures(truth, texture_dir);
  const std::vector<TexturedPlane> planes = truthPlanes(truth, textures);
  Eigen::Vector3d viewpoint = Eigen::Vector3d::Zero();
  for (const auto& [t, pose] : truth_poses) viewpoint += pose.translation();
  if (!truth_poses.empty()) viewpoint /= static_cast<double>(truth_poses.size());
  const core::Isometry T_est_gt = T_gt_est.inverse();

  TextureEvaluation result;
  std::vector<double> psnrs, registered_psnrs, baseline_psnrs;
  std::vector<int> main_planes;  // of result.patches
  double texel_sum_m = 0.0;
  std::size_t bitmaps = 0;
  for (const auto& patch : patches.at("patches")) {
    if (!patch.contains("texture") || patch["texture"].is_null()) continue;
    const auto& texture = patch["texture"];
    cv::Mat rgb, state;
    texture::readBitmapImages(run_dir / texture.at("image").get<std::string>(),
                              run_dir / texture.at("state_image").get<std::string>(), rgb, state);
    const Eigen::Vector3d origin = vec3(patch.at("origin")), u_axis = vec3(patch.at("u_axis")),
                          v_axis = vec3(patch.at("v_axis"));
    const double t = texture.at("texel_m").get<double>();
    texel_sum_m += t;
    ++bitmaps;
    const Eigen::Vector2d grid_origin(texture.at("origin_uv").at(0).get<double>(),
                                      texture.at("origin_uv").at(1).get<double>());
    const Eigen::Vector2d x_axis(texture.at("x_axis").at(0).get<double>(),
                                 texture.at("x_axis").at(1).get<double>());
    const Eigen::Vector2d y_axis(texture.at("y_axis").at(0).get<double>(),
                                 texture.at("y_axis").at(1).get<double>());
    // In the truth's frame: texel (col, row) at fraction (a, b) of its side.
    auto truthPoint = [&](double col, double row) {
      const Eigen::Vector2d uv = grid_origin + t * (col * x_axis + row * y_axis);
      return Eigen::Vector3d(T_gt_est *
                             Eigen::Vector3d(origin + uv.x() * u_axis + uv.y() * v_axis));
    };
    // Candidate planes: those near the patch's centre plane at all (cheap filter per patch).
    const Eigen::Vector3d centre = truthPoint(rgb.cols / 2.0, rgb.rows / 2.0);
    const Eigen::Vector3d normal_gt = T_gt_est.linear() * u_axis.cross(v_axis);
    std::vector<int> candidates;
    for (std::size_t i = 0; i < planes.size(); ++i) {
      const FramedPlane& plane = planes[i].plane;
      if (std::abs(plane.normal.dot(normal_gt)) < std::cos(5.0 * M_PI / 180.0)) continue;
      if (std::abs(plane.normal.dot(centre) - plane.offset) > 0.1) continue;
      candidates.push_back(static_cast<int>(i));
    }

    // The truth on the bitmap's grid, as placed, then shifted in the plane by the offset
    // phase correlation finds between the two (the patch's placement error, which ATE and the
    // plane figures measure; what is left is the texture's own fidelity).
    const auto render = [&](const Eigen::Vector2d& shift) {
      return renderTruth(
          rgb.size(), state,
          [&](double col, double row) { return truthPoint(col + shift.x(), row + shift.y()); },
          planes, candidates, viewpoint, options);
    };
    const TruthImage on_grid = render(Eigen::Vector2d::Zero());
    const Comparison placed = compare(rgb, on_grid);
    if (placed.texels == 0) continue;
    PatchTextureResult patch_result;
    patch_result.patch_id = patch.at("id").get<int>();
    patch_result.texels = placed.texels;
    patch_result.psnr_db = placed.psnr_db;
    const TexturedPlane& main_plane = planes[static_cast<std::size_t>(placed.main_plane)];
    patch_result.plane = main_plane.id;
    patch_result.true_texture = main_plane.texture_id;
    patch_result.observed_texels = static_cast<std::size_t>(
        cv::countNonZero(state == static_cast<int>(texture::TexelState::kObserved)));
    const double max_shift_texels = options.max_shift_m / t;
    const Eigen::Vector2d shift = registrationShift(rgb, on_grid, max_shift_texels);
    patch_result.shift_m = t * shift.norm();
    patch_result.registered_psnr_db = std::max(placed.psnr_db, compare(rgb, render(shift)).psnr_db);
    if (const auto instance = patch.find("instance");
        instance != patch.end() && instance->is_object()) {
      judgePattern(
          *instance, main_plane,
          [&](double col, double row) { return main_plane.plane.uvOf(truthPoint(col, row)); },
          patch_result);
      patch_result.texture_id = instance->at("texture_id").get<std::int64_t>();
      patch_result.reused = instance->value("reused", false);
      if (patch_result.reused) {
        judgeReuse(*renderInstance(patch, run_dir), on_grid, shift, max_shift_texels, render,
                   options, patch_result);
        ++result.reuses;
        if (patch_result.false_match) ++result.false_matches;
      } else {
        ++result.stored;
      }
    }
    if (baseline != nullptr) {
      const cv::Mat mesh = meshColours(
          on_grid,
          [&](double col, double row) { return Eigen::Vector3d(T_est_gt * truthPoint(col, row)); },
          *baseline, options.baseline_max_distance_m);
      const Comparison from_mesh = compare(mesh, on_grid);
      if (from_mesh.texels > 0) {
        patch_result.baseline_psnr_db = from_mesh.psnr_db;
        baseline_psnrs.push_back(from_mesh.psnr_db);
      }
    }
    if (patch_result.pattern_exact) {
      ++result.patterns;
      result.patterns_exact += *patch_result.pattern_exact ? 1 : 0;
    }
    psnrs.push_back(patch_result.psnr_db);
    registered_psnrs.push_back(patch_result.registered_psnr_db);
    result.texels += placed.texels;
    result.patches.push_back(patch_result);
    main_planes.push_back(placed.main_plane);
  }
  auto mean = [](const std::vector<double>& v) {
    double sum = 0.0;
    for (double x : v) sum += x;
    return sum / static_cast<double>(v.size());
  };
  if (!psnrs.empty()) {
    result.psnr_mean_db = mean(psnrs);
    result.psnr_min_db = *std::min_element(psnrs.begin(), psnrs.end());
  }
  if (!registered_psnrs.empty()) result.registered_psnr_mean_db = mean(registered_psnrs);
  if (!baseline_psnrs.empty()) result.baseline_psnr_mean_db = mean(baseline_psnrs);

  result.missed_matches = markMissedMatches(result.patches);
  if (result.reuses > 0) {
    result.false_match_rate =
        static_cast<double>(result.false_matches) / static_cast<double>(result.reuses);
  }
  // The share of the chances to reuse that were missed: a chance is a patch whose true texture
  // was already in the database, taken (a correct reuse) or missed (stored again); false
  // reuses are left out, being neither.
  const std::size_t chances = result.missed_matches + result.reuses - result.false_matches;
  if (chances > 0) {
    result.missed_match_rate =
        static_cast<double>(result.missed_matches) / static_cast<double>(chances);
  }
  if (bitmaps > 0) result.mean_texel_m = texel_sum_m / static_cast<double>(bitmaps);
  if (!result.patches.empty() && result.mean_texel_m) {
    result.ideal_pixels = idealPixels(result.patches, main_planes, planes, *result.mean_texel_m);
  }
  return result;
}

}  // namespace tessera::eval
