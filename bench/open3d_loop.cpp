#include "open3d_loop.h"

#include <chrono>
#include <cstring>

#include <open3d/camera/PinholeCameraIntrinsic.h>
#include <open3d/geometry/Image.h>
#include <open3d/geometry/RGBDImage.h>
#include <open3d/pipelines/integration/ScalableTSDFVolume.h>
#include <open3d/pipelines/odometry/Odometry.h>
#include <open3d/utility/Logging.h>

#include "tessera/core/trajectory.h"

namespace tessera::bench {
namespace {

namespace o3d = open3d;

o3d::geometry::Image legacyImage(const cv::Mat& mat) {
  o3d::geometry::Image image;
  image.Prepare(mat.cols, mat.rows, mat.channels(), static_cast<int>(mat.elemSize1()));
  for (int v = 0; v < mat.rows; ++v) {
    std::memcpy(image.data_.data() + static_cast<std::size_t>(v) * mat.cols * mat.elemSize(),
                mat.ptr(v), mat.cols * mat.elemSize());
  }
  return image;
}

}  // namespace

PlainLoopResult plainOpen3dLoop(const std::vector<core::Frame>& frames,
                                const fusion::TsdfConfig& tsdf) {
  o3d::utility::SetVerbosityLevel(o3d::utility::VerbosityLevel::Error);
  PlainLoopResult result;
  if (frames.empty()) return result;
  o3d::pipelines::integration::ScalableTSDFVolume volume(
      tsdf.voxel_size_m, tsdf.truncation_m, o3d::pipelines::integration::TSDFVolumeColorType::RGB8,
      tsdf.block_resolution);
  core::Trajectory estimate, truth;
  core::Isometry T_W_C = frames.front().T_W_C_gt.value_or(core::Isometry::Identity());
  std::shared_ptr<o3d::geometry::RGBDImage> previous;
  const auto start = std::chrono::steady_clock::now();
  for (const core::Frame& frame : frames) {
    const auto& k = frame.intrinsics;
    const o3d::camera::PinholeCameraIntrinsic intrinsic(k.width, k.height, k.fx, k.fy, k.cx, k.cy);
    const auto colour = legacyImage(frame.rgb);
    const auto depth = legacyImage(frame.depth_mm);
    auto grey = o3d::geometry::RGBDImage::CreateFromColorAndDepth(colour, depth, 1000.0, 4.0);
    if (previous) {
      const auto [ok, T_previous_current, information] =
          o3d::pipelines::odometry::ComputeRGBDOdometry(*grey, *previous, intrinsic);
      if (ok) {
        T_W_C = T_W_C * core::Isometry(T_previous_current);
      } else {
        ++result.odometry_failures;
      }
    }
    const auto rgb =
        o3d::geometry::RGBDImage::CreateFromColorAndDepth(colour, depth, 1000.0, 4.0, false);
    volume.Integrate(*rgb, intrinsic, T_W_C.inverse().matrix());
    previous = grey;
    estimate[frame.timestamp_ns] = T_W_C;
    if (frame.T_W_C_gt) truth[frame.timestamp_ns] = *frame.T_W_C_gt;
  }
  result.ms_per_frame =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count() /
      static_cast<double>(frames.size());
  if (truth.size() == estimate.size()) {
    if (const auto ate = core::absoluteTrajectoryError(estimate, truth)) {
      result.ate_mm = ate->rmse_m * 1e3;
      result.ate_poses = static_cast<int>(ate->pairs);
    }
  }
  return result;
}

}  // namespace tessera::bench
