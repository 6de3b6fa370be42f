#include "tessera/drivers/oni/openni_runtime.h"

#include <cmath>
#include <mutex>

#include <OpenNI.h>
#include <fmt/format.h>

#include "tessera/core/error.h"

namespace tessera::drivers::oni {

void ensureOpenNi() {
  static std::once_flag once;
  static openni::Status status = openni::STATUS_OK;
  std::call_once(once, [] { status = openni::OpenNI::initialize(); });
  if (status != openni::STATUS_OK) {
    throw core::SourceError(
        fmt::format("OpenNI2 failed to initialise: {}", openni::OpenNI::getExtendedError()));
  }
}

core::Intrinsics intrinsicsFromFov(int width, int height, double hfov_rad, double vfov_rad) {
  core::Intrinsics k;
  k.width = width;
  k.height = height;
  k.fx = width / (2.0 * std::tan(hfov_rad / 2.0));
  k.fy = height / (2.0 * std::tan(vfov_rad / 2.0));
  k.cx = width / 2.0;
  k.cy = height / 2.0;
  return k;
}

}  // namespace tessera::drivers::oni
