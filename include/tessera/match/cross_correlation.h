#pragma once
// Zero-mean normalised cross-correlation of a tile at every offset inside an image, normalised
// per window (the image's mean and spread under the tile at that offset, not over the whole
// image): correlated by DFT, each window normalised from integral images (as OpenCV's
// matchTemplate with TM_CCOEFF_NORMED), and one DFT of a tile serving two of its quarter turns.
#include <opencv2/core/mat.hpp>

namespace tessera::match {

struct CorrelationPeak {
  int x = 0, y = 0;     // top-left corner of the best placement of the tile in the image
  double score = -1.0;  // its NCC in [-1, 1]
};

// Grey float image of an RGB bitmap (CV_8UC3); texels outside `mask` (CV_8UC1, 0 = outside;
// empty: none) take the mean grey of those inside, so they add no structure.
cv::Mat greyForCorrelation(const cv::Mat& rgb, const cv::Mat& mask);

// The NCC of `tile` at every placement inside `image` (both CV_32FC1 from greyForCorrelation;
// the tile no larger than the image): a (H - h + 1) x (W - w + 1) CV_32FC1 map.
cv::Mat normalisedCrossCorrelation(const cv::Mat& image, const cv::Mat& tile);

// The highest peak of that map. A flat window (no variance) scores 0.
CorrelationPeak findTile(const cv::Mat& image, const cv::Mat& tile);

// An image turned clockwise by `turns` quarter turns (cv::rotate); 0 turns: the image itself.
cv::Mat turned(const cv::Mat& image, int turns);

struct TurnedPeak {
  CorrelationPeak peak;
  int turns = 0;  // of the tile (or of the moving image), clockwise
};

// The best placement inside `image` of `tile` turned by 0 to 3 quarter turns (turned()), over
// the turns at which it fits; a score of -1 when it fits at none. The image's DFT is taken
// once, and each tile DFT serves two turns, half a turn apart.
TurnedPeak findTileAtAnyTurn(const cv::Mat& image, const cv::Mat& tile);

// Two textures that overlap in part, neither inside the other (the same floor seen from two
// places): the shift (x, y) at which `moving`'s origin sits in `fixed`'s frame, so that
// fixed(p) ~ moving(p - (x, y)), that best correlates the two over the texels both cover:
// masked normalised cross-correlation over every shift by six DFT products (Padfield, "Masked
// object registration in the Fourier domain", 2012). Shifts whose common texels number fewer
// than `min_overlap` are not considered. Both images CV_32FC1 from greyForCorrelation, masks
// CV_8UC1 (0 = no texel). A score of -1 when no shift has that overlap.
CorrelationPeak findOverlap(const cv::Mat& fixed, const cv::Mat& fixed_mask, const cv::Mat& moving,
                            const cv::Mat& moving_mask, double min_overlap);

// findOverlap's best placement of `moving` turned by 0 to 3 quarter turns (turned(); the
// turn's mask with it): the fixed image's spectra are taken once, and each set of the moving
// image's serves two turns, half a turn apart. A score of -1 when no turn has a placement.
TurnedPeak findOverlapAtAnyTurn(const cv::Mat& fixed, const cv::Mat& fixed_mask,
                                const cv::Mat& moving, const cv::Mat& moving_mask,
                                double min_overlap);

// The same score computed directly at the shifts within `radius` of `start` (each costs the
// overlap's texels): a shift found on scaled-down images, made exact at full size.
CorrelationPeak refineOverlap(const cv::Mat& fixed, const cv::Mat& fixed_mask,
                              const cv::Mat& moving, const cv::Mat& moving_mask,
                              const CorrelationPeak& start, int radius, double min_overlap);

}  // namespace tessera::match
