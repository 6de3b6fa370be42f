#pragma once
// Photometric compensation between frames: a real camera changes exposure and white balance
// from frame to frame, so the same surface arrives with a different colour in each. A frame's
// gain per channel is estimated where it overlaps what the patches already hold, and applied to
// its samples before they are blended (global colour adjustment in multi-view texturing, as in
// Waechter et al. 2014, reduced to one gain per channel and frame).
#include <cstddef>
#include <optional>
#include <vector>

#include <Eigen/Core>

namespace tessera::planes {

struct ColourPair {
  Eigen::Vector3f observed;   // RGB of a pixel of the new frame
  Eigen::Vector3f reference;  // the blended colour the patch holds at that pixel's position
};

// The per-channel gain g with reference ~ g * observed, robust to outliers (specular
// highlights, a misregistered edge): pairs whose brightness ratio is far from the median ratio
// are dropped, then g_c = sum reference_c / sum observed_c over the rest. Pairs with a clipped
// or near-black channel say nothing about the gain and are skipped. Nothing when fewer than
// min_pairs pairs remain.
std::optional<Eigen::Vector3f> estimateGain(const std::vector<ColourPair>& pairs,
                                            std::size_t min_pairs = 200);

}  // namespace tessera::planes
