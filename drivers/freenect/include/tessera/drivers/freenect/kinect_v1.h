#pragma once
// The Kinect v1 model the freenect source uses when the device does not tell: the conversion
// of raw 11-bit disparity to depth and typical camera parameters at 640x480. The typical values
// fit most devices to a few pixels; pass a calibration (FreenectOptions) for better ones.
#include <cstdint>

#include <opencv2/core/mat.hpp>

#include "tessera/core/frame.h"

namespace tessera::drivers::freenect {

// Raw value of a pixel without depth (FREENECT_DEPTH_RAW_NO_VALUE).
constexpr std::uint16_t kRawNoDepth = 2047;
// Device timestamps count ticks of a 60 MHz clock (libfreenect issue #681, PR #465) and wrap
// around every 2^32 ticks (71.6 s); both cameras share that clock.
constexpr std::int64_t kDeviceClockHz = 60'000'000;
constexpr std::int64_t kFrameTicks = kDeviceClockHz / 30;  // the cameras run at 30 Hz

// Millimetres for a raw 11-bit disparity, 0 when there is no depth or it is beyond 10 m.
// N. Burrus, "Kinect calibration" (2011), also on the OpenKinect wiki ("Imaging Information"):
//   z [m] = 1 / (raw * -0.0030711016 + 3.3309495161)
std::uint16_t disparityToMm(std::uint16_t raw);

// Converts a CV_16UC1 image of raw disparities to CV_16UC1 millimetres (0 = invalid).
cv::Mat disparityImageToMm(const cv::Mat& raw);

// The depth (IR) camera: f from the device's reference plane (120 mm away, 0.1042 mm pixels at
// 1280x1024, halved for 640x480: f = 120 / 0.2084 = 575.8 px), principal point at the centre.
core::Intrinsics typicalDepthIntrinsics();
// The RGB camera: fx = fy = 525, (319.5, 239.5), the values ROS and the TUM RGB-D benchmark use
// for a Kinect v1 without calibration. Registered depth is in this camera's pixel grid.
core::Intrinsics typicalColourIntrinsics();
// The RGB camera seen from the depth camera: no rotation, 2.5 cm apart along the image x axis
// (the RGB camera sits on the depth camera's -x side, so depth points move +2.5 cm in x).
core::ColourCamera typicalColourCamera();

}  // namespace tessera::drivers::freenect
