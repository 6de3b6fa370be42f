#include "tessera/eval/texture_evaluation.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <mutex>

#include <Eigen/Geometry>
#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/core/utility.hpp>

#include "tessera/core/config.h"
#include "tessera/core/error.h"
#include "tessera/drivers/synthetic/texture.h"
#include "tessera/fusion/mesh_colours.h"
#include "tessera/texture/bitmap_builder.h"
#include "tessera/texture/bitmap_export.h"
#include "truth_geometry.h"

namespace tessera::eval {

namespace {

using drivers::synthetic::Texture;

struct TexturedPlane {
  std::string id;
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
    const nlohmann::json& truth,
    const std::map<std::string, std::unique_ptr<Texture>>& textures) {
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

struct Sums {
  double squared = 0.0, baseline_squared = 0.0;
  std::size_t texels = 0, baseline_texels = 0;
  std::map<int, std::size_t> plane_votes;
  void add(const Sums& other) {
    squared += other.squared, baseline_squared += other.baseline_squared;
    texels += other.texels, baseline_texels += other.baseline_texels;
    for (const auto& [plane, votes] : other.plane_votes) plane_votes[plane] += votes;
  }
};

}  // namespace

TextureEvaluation evaluateTextures(const nlohmann::json& truth,
                                   const std::filesystem::path& truth_dir,
                                   const Trajectory& truth_poses, const nlohmann::json& patches,
                                   const std::filesystem::path& run_dir,
                                   const core::Isometry& T_gt_est,
                                   const fusion::MeshColourSampler* baseline,
                                   const TextureEvaluationOptions& options) {
  const auto textures = truthTextures(truth, truth_dir);
  const std::vector<TexturedPlane> planes = truthPlanes(truth, textures);
  Eigen::Vector3d viewpoint = Eigen::Vector3d::Zero();
  for (const auto& [t, pose] : truth_poses) viewpoint += pose.translation();
  if (!truth_poses.empty()) viewpoint /= static_cast<double>(truth_poses.size());
  const core::Isometry T_est_gt = T_gt_est.inverse();

  TextureEvaluation result;
  std::vector<double> psnrs, baseline_psnrs;
  for (const auto& patch : patches.at("patches")) {
    if (!patch.contains("texture") || patch["texture"].is_null()) continue;
    const auto& texture = patch["texture"];
    cv::Mat rgb, state;
    texture::readBitmapImages(run_dir / texture.at("image").get<std::string>(),
                              run_dir / texture.at("state_image").get<std::string>(), rgb, state);
    const Eigen::Vector3d origin = vec3(patch.at("origin")), u_axis = vec3(patch.at("u_axis")),
                          v_axis = vec3(patch.at("v_axis"));
    const double t = texture.at("texel_m").get<double>();
    const Eigen::Vector2d grid_origin(texture.at("origin_uv").at(0).get<double>(),
                                      texture.at("origin_uv").at(1).get<double>());
    const Eigen::Vector2d x_axis(texture.at("x_axis").at(0).get<double>(),
                                 texture.at("x_axis").at(1).get<double>());
    const Eigen::Vector2d y_axis(texture.at("y_axis").at(0).get<double>(),
                                 texture.at("y_axis").at(1).get<double>());
    // In the truth's frame: texel (col, row) at fraction (a, b) of its side.
    auto truthPoint = [&](double col, double row) {
      const Eigen::Vector2d uv = grid_origin + t * (col * x_axis + row * y_axis);
      return Eigen::Vector3d(T_gt_est * Eigen::Vector3d(origin + uv.x() * u_axis + uv.y() * v_axis));
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

    Sums sums;
    std::mutex merge;
    const int s = std::max(1, options.supersample);
    cv::parallel_for_(cv::Range(0, rgb.rows), [&](const cv::Range& rows) {
      Sums local;
      for (int r = rows.start; r < rows.end; ++r) {
        for (int c = 0; c < rgb.cols; ++c) {
          if (state.at<std::uint8_t>(r, c) !=
              static_cast<int>(texture::TexelState::kObserved)) {
            continue;
          }
          // The true colour averaged over the texel, if all of it lies on one true plane.
          cv::Vec3d truth_colour(0, 0, 0);
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
              truth_colour += cv::Vec3d(p.colourAt(p.plane.uvOf(X)));
            }
          }
          if (plane < 0) continue;
          truth_colour /= static_cast<double>(s * s);
          const cv::Vec3b& got = rgb.at<cv::Vec3b>(r, c);
          for (int k = 0; k < 3; ++k) local.squared += std::pow(got[k] - truth_colour[k], 2);
          local.texels += 1;
          local.plane_votes[plane] += 1;
          if (baseline != nullptr) {
            const Eigen::Vector3d X_est = T_est_gt * truthPoint(c + 0.5, r + 0.5);
            if (const auto mesh = baseline->colourAt(X_est, options.baseline_max_distance_m)) {
              for (int k = 0; k < 3; ++k) {
                local.baseline_squared += std::pow((*mesh)[k] - truth_colour[k], 2);
              }
              local.baseline_texels += 1;
            }
          }
        }
      }
      const std::lock_guard<std::mutex> lock(merge);
      sums.add(local);
    });
    if (sums.texels == 0) continue;
    PatchTextureResult patch_result;
    patch_result.patch_id = patch.at("id").get<int>();
    patch_result.texels = sums.texels;
    patch_result.psnr_db = psnrOf(sums.squared, 3 * sums.texels);
    const auto top = std::max_element(sums.plane_votes.begin(), sums.plane_votes.end(),
                                      [](const auto& a, const auto& b) { return a.second < b.second; });
    patch_result.plane = planes[static_cast<std::size_t>(top->first)].id;
    if (sums.baseline_texels > 0) {
      patch_result.baseline_psnr_db = psnrOf(sums.baseline_squared, 3 * sums.baseline_texels);
      baseline_psnrs.push_back(*patch_result.baseline_psnr_db);
    }
    psnrs.push_back(patch_result.psnr_db);
    result.texels += sums.texels;
    result.patches.push_back(patch_result);
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
  if (!baseline_psnrs.empty()) result.baseline_psnr_mean_db = mean(baseline_psnrs);
  return result;
}

}  // namespace tessera::eval
