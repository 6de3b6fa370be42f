#pragma once
// What every OpenNI2 user in tessera shares: the library's one-time start, and intrinsics from
// the field of view a stream reports (OpenNI2 gives no focal lengths or principal point).
#include "tessera/core/intrinsics.h"

namespace tessera::drivers::oni {

// Starts OpenNI2 once per process; it stays up (its shutdown would close every open device).
// Throws core::SourceError with OpenNI2's own message when it cannot start. Thread-safe.
void ensureOpenNi();

// Pinhole intrinsics of a width x height image with these fields of view (radians), principal
// point at the centre: f = size / (2 tan(fov / 2)).
core::Intrinsics intrinsicsFromFov(int width, int height, double hfov_rad, double vfov_rad);

}  // namespace tessera::drivers::oni
