#pragma once
// Colour-to-depth registration for sensors whose colour camera sits beside the depth camera.
#include <opencv2/core/mat.hpp>

#include "tessera/core/frame.h"

namespace tessera::core {

// The colour of every depth pixel: each valid depth pixel is back-projected, moved into the
// colour camera (T_RGB_D), projected with the colour intrinsics and sampled bilinearly.
// Pixels without depth, or that fall outside the colour image, are black. Returns rgb as is
// when the frame has no separate colour camera.
cv::Mat registerColourToDepth(const Frame& frame);

// The same frame with rgb registered to depth and colour_camera cleared.
Frame withRegisteredColour(Frame frame);

}  // namespace tessera::core
