#pragma once
// One RGB-D frame as every stage sees it.
#include <cstdint>
#include <optional>

#include <opencv2/core/mat.hpp>

#include "tessera/core/intrinsics.h"
#include "tessera/core/pose.h"

namespace tessera::core {

// A colour camera separate from the depth camera (colour not registered to depth).
struct ColourCamera {
  Intrinsics intrinsics;
  Isometry T_RGB_D = Isometry::Identity();  // depth-camera coordinates -> colour-camera ones
};

struct Frame {
  std::uint64_t index = 0;           // position in the source, from 0
  std::int64_t timestamp_ns = 0;     // capture time (of the depth image), on the source's clock
  // When the colour image was taken, on the same clock, where the source says: a Kinect v1
  // does not synchronise its two cameras, so colour and depth are some milliseconds apart.
  std::optional<std::int64_t> colour_timestamp_ns;
  // Live sources: when the frame reached this host (steady clock, ns since its epoch), for the
  // capture-to-fusion latency. 0 for recordings.
  std::int64_t arrival_ns = 0;
  cv::Mat depth_mm;                  // CV_16UC1, millimetres, 0 = invalid
  cv::Mat rgb;                       // CV_8UC3 in R, G, B order
  Intrinsics intrinsics;             // of depth_mm (and of a registered rgb)
  std::optional<Isometry> T_W_C_gt;  // ground-truth camera-to-world pose, when the source has one
  // Set when rgb comes from its own camera; empty when rgb is registered to depth, pixel for
  // pixel. core::registerColourToDepth() resamples it onto the depth image.
  std::optional<ColourCamera> colour_camera;
  // A marker without images: the live source was interrupted here (device unplugged or
  // stalled). The stages finalize what they have; frames after it may come from a new session.
  bool source_interrupted = false;
};

// Whether frame `index` is left out of fusion and texturing by `tessera run --holdout-every N`
// (every N-th frame: N-1, 2N-1, ...; the first frame always builds the map), to be scored
// apart by `tessera eval --frames`. 0 or 1: none.
inline bool isHeldOut(std::uint64_t index, int holdout_every) {
  return holdout_every > 1 && (index + 1) % static_cast<std::uint64_t>(holdout_every) == 0;
}

}  // namespace tessera::core
