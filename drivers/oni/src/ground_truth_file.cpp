#include "tessera/drivers/oni/ground_truth_file.h"

#include <fstream>

#include <fmt/format.h>

#include "tessera/core/error.h"

namespace tessera::drivers::oni {

nlohmann::json poseToJson(const core::Isometry& T) {
  const Eigen::Quaterniond q(T.rotation());
  const Eigen::Vector3d t = T.translation();
  return {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()};
}

std::optional<core::Isometry> poseFromJson(const nlohmann::json& value) {
  if (!value.is_array() || value.size() != 7) return std::nullopt;
  const auto p = value.get<std::vector<double>>();
  return core::isometryFromTranslationQuaternion(Eigen::Vector3d(p[0], p[1], p[2]), p[3], p[4],
                                                 p[5], p[6]);
}

nlohmann::json intrinsicsToJson(const core::Intrinsics& k) {
  return {{"fx", k.fx}, {"fy", k.fy},       {"cx", k.cx},
          {"cy", k.cy}, {"width", k.width}, {"height", k.height}};
}

core::Intrinsics intrinsicsFromJson(const nlohmann::json& value) {
  core::Intrinsics k;
  k.fx = value.value("fx", 0.0), k.fy = value.value("fy", 0.0);
  k.cx = value.value("cx", 0.0), k.cy = value.value("cy", 0.0);
  k.width = value.value("width", 0), k.height = value.value("height", 0);
  return k;
}

void GroundTruthFile::setIntrinsics(const core::Intrinsics& k) {
  intrinsics_ = intrinsicsToJson(k);
}

void GroundTruthFile::setColourCamera(const core::ColourCamera& camera) {
  colour_camera_ = {{"intrinsics", intrinsicsToJson(camera.intrinsics)},
                    {"T_RGB_D", poseToJson(camera.T_RGB_D)}};
}

void GroundTruthFile::addFrame(const core::Frame& frame) {
  nlohmann::json entry = {{"index", frames_.size()}, {"timestamp_ns", frame.timestamp_ns}};
  if (frame.T_W_C_gt) {
    entry["T_W_C"] = poseToJson(*frame.T_W_C_gt);
    ++frames_with_pose_;
  }
  frames_.push_back(std::move(entry));
}

void GroundTruthFile::write(const std::filesystem::path& path) const {
  nlohmann::json doc = extra_;
  doc["format"] = "tessera ground truth 1";
  doc["intrinsics"] = intrinsics_;
  doc["colour_camera"] = colour_camera_;
  doc["frames"] = frames_;
  std::ofstream out(path);
  out << doc.dump(1) << '\n';
  out.close();
  if (!out) throw core::Error(fmt::format("{}: cannot write the ground truth", path.string()));
}

}  // namespace tessera::drivers::oni
