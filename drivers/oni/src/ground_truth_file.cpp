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

void GroundTruthFile::setIntrinsics(const core::Intrinsics& k) {
  intrinsics_ = {{"fx", k.fx}, {"fy", k.fy}, {"cx", k.cx},
                 {"cy", k.cy}, {"width", k.width}, {"height", k.height}};
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
  doc["frames"] = frames_;
  std::ofstream out(path);
  out << doc.dump(1) << '\n';
  out.close();
  if (!out) throw core::Error(fmt::format("{}: cannot write the ground truth", path.string()));
}

}  // namespace tessera::drivers::oni
