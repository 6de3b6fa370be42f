#include "tessera/drivers/synthetic/scene_ground_truth.h"

namespace tessera::drivers::synthetic {

namespace {

nlohmann::json vec(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }
nlohmann::json vec(const Eigen::Vector2d& v) { return {v.x(), v.y()}; }

}  // namespace

nlohmann::json sceneGroundTruth(const Scene& scene) {
  nlohmann::json textures = nlohmann::json::array();
  for (const auto& [id, texture] : scene.textures) {
    nlohmann::json entry = {{"id", id}, {"generator", texture->generator()}};
    const auto lattice = texture->lattice();
    entry["periodic"] = lattice.has_value();
    entry["lattice_m"] =
        lattice ? nlohmann::json{vec((*lattice)[0]), vec((*lattice)[1])} : nlohmann::json(nullptr);
    const auto extent = texture->extent();
    entry["extent_m"] = extent ? vec(*extent) : nlohmann::json(nullptr);
    // The scene entry itself, so that evaluation can rebuild the exact texture.
    const auto definition = scene.texture_definitions.find(id);
    entry["definition_yaml"] = definition != scene.texture_definitions.end()
                                   ? nlohmann::json(definition->second)
                                   : nlohmann::json(nullptr);
    textures.push_back(entry);
  }

  nlohmann::json planes = nlohmann::json::array();
  for (const ScenePlane& plane : scene.planes) {
    nlohmann::json outline = nlohmann::json::array(), outline_world = nlohmann::json::array();
    for (const auto& p : plane.polygon) {
      outline.push_back(vec(p));
      outline_world.push_back(
          vec(Eigen::Vector3d(plane.origin + p.x() * plane.u_axis + p.y() * plane.v_axis)));
    }
    nlohmann::json entry = {
        {"id", plane.id},
        {"normal", vec(plane.normal)},
        {"offset_m", plane.offset()},
        {"origin", vec(plane.origin)},
        {"u_axis", vec(plane.u_axis)},
        {"v_axis", vec(plane.v_axis)},
        {"polygon_uv", outline},
        {"polygon_world", outline_world},
        {"area_m2", plane.area()},
        {"texture", plane.texture_id},
        // (s, t) = R(rotation) (u, v) / scale + offset
        {"texture_to_plane",
         {{"rotation_rad", plane.texture_rotation_rad},
          {"scale", plane.texture_scale},
          {"offset_m", vec(plane.texture_offset_m)}}},
    };
    // The period lattice on the plane, in (u, v): each texture period vector mapped back.
    if (const auto lattice = plane.texture->lattice()) {
      const Eigen::Rotation2Dd back(-plane.texture_rotation_rad);
      entry["lattice_uv_m"] = {vec(Eigen::Vector2d(plane.texture_scale * (back * (*lattice)[0]))),
                               vec(Eigen::Vector2d(plane.texture_scale * (back * (*lattice)[1])))};
    } else {
      entry["lattice_uv_m"] = nullptr;
    }
    planes.push_back(entry);
  }

  const SensorProfile& sensor = scene.sensor;
  return {{"scene", scene.name},
          {"scene_dir", scene.directory.string()},
          {"seed", scene.seed},
          {"sensor",
           {{"profile", sensor.name},
            {"min_depth_m", sensor.min_depth_m},
            {"max_depth_m", sensor.max_depth_m},
            {"disparity_quantisation", sensor.disparity_quantisation},
            {"colour_registered", sensor.colour_registered},
            {"noise_sigma_m",
             {{"a", sensor.noise_a_m}, {"b", sensor.noise_b}, {"c", sensor.noise_c_m}}}}},
          {"textures", textures},
          {"planes", planes}};
}

}  // namespace tessera::drivers::synthetic
