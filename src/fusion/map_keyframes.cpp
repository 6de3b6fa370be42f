#include "tessera/fusion/map_keyframes.h"

#include <cstdint>
#include <memory>

#include "tessera/core/binary_file.h"

namespace tessera::fusion {

namespace {

constexpr char kTag[] = "tessera-keyframes";
constexpr std::uint32_t kFormat = 1;
constexpr std::size_t kMaxItems = 1U << 24U;  // far above any real map
constexpr int kDescriptorBytes = 32;          // ORB
// A keyframe without features: its time, its pose and two zero counts.
constexpr std::size_t kKeyframeBytes = sizeof(std::int64_t) + 16 * sizeof(double) + 16;

// A keypoint and its point in the camera, as stored.
struct StoredFeature {
  float x, y, size, angle, response;
  std::int32_t octave, class_id;
  float X, Y, Z;  // NaN where it has no depth
};

}  // namespace

void writeMapKeyframes(const std::filesystem::path& path,
                       const std::vector<MapKeyframe>& keyframes) {
  core::BinaryWriter out(path, kTag, kFormat);
  out.value(static_cast<std::uint64_t>(keyframes.size()));
  for (const MapKeyframe& keyframe : keyframes) {
    out.value(keyframe.timestamp_ns);
    const Eigen::Matrix4d T = keyframe.T_W_C.matrix();
    for (int i = 0; i < 16; ++i) out.value(T(i));
    const FeatureFrame& f = *keyframe.features;
    std::vector<StoredFeature> features;
    features.reserve(f.keypoints.size());
    for (std::size_t i = 0; i < f.keypoints.size(); ++i) {
      const cv::KeyPoint& k = f.keypoints[i];
      const cv::Point3f p = i < f.points_C.size() ? f.points_C[i] : cv::Point3f(NAN, NAN, NAN);
      features.push_back(
          {k.pt.x, k.pt.y, k.size, k.angle, k.response, k.octave, k.class_id, p.x, p.y, p.z});
    }
    out.values(features);
    const cv::Mat rows = f.descriptors.isContinuous() ? f.descriptors : f.descriptors.clone();
    out.value(static_cast<std::uint64_t>(rows.empty() ? 0 : rows.rows));
    if (!rows.empty()) out.bytes(rows.data, rows.total() * rows.elemSize());
  }
  out.finish();
}

std::vector<MapKeyframe> readMapKeyframes(const std::filesystem::path& path) {
  core::BinaryReader in(path, kTag, kFormat);
  std::vector<MapKeyframe> keyframes(in.count(kMaxItems, kKeyframeBytes));
  for (MapKeyframe& keyframe : keyframes) {
    keyframe.timestamp_ns = in.value<std::int64_t>();
    Eigen::Matrix4d T;
    for (int i = 0; i < 16; ++i) T(i) = in.value<double>();
    keyframe.T_W_C.matrix() = T;
    const auto features = in.values<StoredFeature>(kMaxItems);
    auto read = std::make_shared<FeatureFrame>();
    FeatureFrame& f = *read;
    for (const StoredFeature& s : features) {
      f.keypoints.emplace_back(s.x, s.y, s.size, s.angle, s.response, s.octave, s.class_id);
      f.points_C.emplace_back(s.X, s.Y, s.Z);
    }
    const std::size_t rows = in.count(kMaxItems, kDescriptorBytes);
    if (rows != 0 && rows != features.size()) {
      in.corrupt(fmt::format("{} descriptors for {} keypoints", rows, features.size()));
    }
    if (rows > 0) {
      f.descriptors.create(static_cast<int>(rows), kDescriptorBytes, CV_8U);
      in.bytes(f.descriptors.data, f.descriptors.total());
    }
    keyframe.features = std::move(read);
  }
  in.expectEnd();
  return keyframes;
}

}  // namespace tessera::fusion
