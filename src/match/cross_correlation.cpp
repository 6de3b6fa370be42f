#include "tessera/match/cross_correlation.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"

namespace tessera::match {
namespace {

// Windows (and tiles) whose grey standard deviation is below this are flat: far below the
// quantisation noise of 8-bit images, so they hold no structure, and their NCC would be the
// ratio of two rounding errors.
constexpr double kFlatStdDev = 0.05;

void requireGrey(const cv::Mat& image, const char* function, const char* what) {
  if (image.empty() || image.type() != CV_32FC1) {
    throw core::Error(fmt::format("{}: the {} must be a non-empty CV_32FC1", function, what));
  }
}

}  // namespace

cv::Mat greyForCorrelation(const cv::Mat& rgb, const cv::Mat& mask) {
  if (rgb.empty() || rgb.type() != CV_8UC3) {
    throw core::Error("greyForCorrelation: the image must be a non-empty CV_8UC3");
  }
  if (!mask.empty() && (mask.type() != CV_8UC1 || mask.size() != rgb.size())) {
    throw core::Error("greyForCorrelation: the mask must be CV_8UC1 of the image's size");
  }
  cv::Mat colour, grey;
  rgb.convertTo(colour, CV_32FC3);
  cv::cvtColor(colour, grey, cv::COLOR_RGB2GRAY);
  if (!mask.empty()) {
    cv::Mat outside;
    cv::compare(mask, 0, outside, cv::CMP_EQ);
    const bool any_inside = cv::countNonZero(mask) > 0;
    grey.setTo(any_inside ? cv::mean(grey, mask)[0] : 0.0, outside);
  }
  return grey;
}

namespace {

// An image made ready to be correlated with tiles: its spectrum at a size the DFT likes, no
// smaller than the image, so that no placement inside it wraps round; and its integral images,
// which give each window's spread. The correlation of a tile T (h x w, zero mean) at offset d is
// corr(d) = sum_p I(d + p) T(p); with R = T turned half round, R(p) = T(size - 1 - p), it is
// sum_q I(d + size - 1 - q) T(q) = (I * T)(d + size - 1), the convolution read further on. So
// one DFT of a tile gives its NCC at two turns.
class TileCorrelator {
 public:
  explicit TileCorrelator(const cv::Mat& image)
      : image_size_(image.size()),
        padded_(cv::getOptimalDFTSize(image.cols), cv::getOptimalDFTSize(image.rows)) {
    // Less its mean, which changes no correlation with a zero-mean tile and keeps the float
    // DFT's rounding small beside the structure.
    cv::Mat canvas = cv::Mat::zeros(padded_, CV_32FC1);
    cv::subtract(image, cv::mean(image), canvas(cv::Rect(cv::Point(), image_size_)));
    cv::dft(canvas, spectrum_, 0, image.rows);
    cv::integral(image, sum_, square_sum_, CV_64F, CV_64F);
  }

  // The NCC maps of `tile` and, if `half_turn_too`, of the tile turned half round ({} if not).
  std::pair<cv::Mat, cv::Mat> ncc(const cv::Mat& tile, bool half_turn_too) const {
    const cv::Size valid(image_size_.width - tile.cols + 1, image_size_.height - tile.rows + 1);
    cv::Scalar tile_mean, tile_std;
    cv::meanStdDev(tile, tile_mean, tile_std);
    // A flat tile matches nothing.
    if (tile_std[0] < kFlatStdDev) {
      return {cv::Mat::zeros(valid, CV_32FC1),
              half_turn_too ? cv::Mat::zeros(valid, CV_32FC1) : cv::Mat()};
    }
    cv::Mat canvas = cv::Mat::zeros(padded_, CV_32FC1);
    cv::subtract(tile, tile_mean, canvas(cv::Rect(cv::Point(), tile.size())));
    cv::Mat tile_spectrum;
    cv::dft(canvas, tile_spectrum, 0, tile.rows);
    // Sum of the zero-mean tile's squares: its variance times its texels.
    const double tile_energy = tile_std[0] * tile_std[0] * static_cast<double>(tile.total());
    const cv::Rect at_origin(cv::Point(), valid);
    // The windows' spreads are the same for both maps: worked out once.
    const cv::Mat spread = spreads(tile.size(), tile_energy);
    cv::Mat first =
        normalise(transform(tile_spectrum, /*conjugate=*/true, valid.height)(at_origin), spread);
    if (!half_turn_too) return {first, {}};
    const cv::Rect further_on(cv::Point(tile.cols - 1, tile.rows - 1), valid);
    return {first,
            normalise(transform(tile_spectrum, false, image_size_.height)(further_on), spread)};
  }

 private:
  // The image's correlation with the tile (conjugate) or convolution with it, its first `rows`
  // rows computed (the rest of the padded output is not read).
  cv::Mat transform(const cv::Mat& tile_spectrum, bool conjugate, int rows) const {
    cv::Mat product, out;
    cv::mulSpectrums(spectrum_, tile_spectrum, product, 0, conjugate);
    cv::idft(product, out, cv::DFT_SCALE | cv::DFT_REAL_OUTPUT, rows);
    return out;
  }

  // Each window's spread times the tile's, sqrt(window variance x area x tile energy), from the
  // integral images in double; 0 for a flat window (then it scores 0).
  cv::Mat spreads(const cv::Size& tile_size, double tile_energy) const {
    const cv::Size valid(image_size_.width - tile_size.width + 1,
                         image_size_.height - tile_size.height + 1);
    cv::Mat spread(valid, CV_64FC1);
    const double area = static_cast<double>(tile_size.area());
    const double min_variance = kFlatStdDev * kFlatStdDev;
    for (int y = 0; y < valid.height; ++y) {
      auto* out = spread.ptr<double>(y);
      const auto* s0 = sum_.ptr<double>(y);
      const auto* s1 = sum_.ptr<double>(y + tile_size.height);
      const auto* q0 = square_sum_.ptr<double>(y);
      const auto* q1 = square_sum_.ptr<double>(y + tile_size.height);
      for (int x = 0; x < valid.width; ++x) {
        const int x1 = x + tile_size.width;
        const double sum = s1[x1] - s1[x] - s0[x1] + s0[x];
        const double variance =
            (q1[x1] - q1[x] - q0[x1] + q0[x]) / area - (sum / area) * (sum / area);
        out[x] = variance < min_variance ? 0.0 : std::sqrt(variance * area * tile_energy);
      }
    }
    return spread;
  }

  // Correlation over the windows' spreads (spreads()): the NCC, clamped to [-1, 1].
  static cv::Mat normalise(const cv::Mat& correlation, const cv::Mat& spread) {
    cv::Mat ncc(correlation.size(), CV_32FC1);
    for (int y = 0; y < ncc.rows; ++y) {
      auto* out = ncc.ptr<float>(y);
      const auto* in = correlation.ptr<float>(y);
      const auto* by = spread.ptr<double>(y);
      for (int x = 0; x < ncc.cols; ++x) {
        const double score = in[x] / by[x];
        out[x] = by[x] == 0.0 || !std::isfinite(score)
                     ? 0.0F
                     : static_cast<float>(std::clamp(score, -1.0, 1.0));
      }
    }
    return ncc;
  }

  cv::Size image_size_, padded_;
  cv::Mat spectrum_, sum_, square_sum_;
};

bool fitsInside(const cv::Mat& tile, const cv::Mat& image) {
  return tile.cols <= image.cols && tile.rows <= image.rows;
}

CorrelationPeak peakOf(const cv::Mat& ncc) {
  double best = 0.0;
  cv::Point at;
  cv::minMaxLoc(ncc, nullptr, &best, nullptr, &at);
  return {at.x, at.y, best};
}

}  // namespace

cv::Mat normalisedCrossCorrelation(const cv::Mat& image, const cv::Mat& tile) {
  requireGrey(image, "normalisedCrossCorrelation", "image");
  requireGrey(tile, "normalisedCrossCorrelation", "tile");
  if (!fitsInside(tile, image)) {
    throw core::Error(fmt::format("normalisedCrossCorrelation: tile {}x{} larger than image {}x{}",
                                  tile.cols, tile.rows, image.cols, image.rows));
  }
  return TileCorrelator(image).ncc(tile, false).first;
}

CorrelationPeak findTile(const cv::Mat& image, const cv::Mat& tile) {
  return peakOf(normalisedCrossCorrelation(image, tile));
}

cv::Mat turned(const cv::Mat& image, int turns) {
  if (turns % 4 == 0) return image;
  cv::Mat out;
  const int codes[] = {0, cv::ROTATE_90_CLOCKWISE, cv::ROTATE_180, cv::ROTATE_90_COUNTERCLOCKWISE};
  cv::rotate(image, out, codes[turns % 4]);
  return out;
}

TurnedPeak findTileAtAnyTurn(const cv::Mat& image, const cv::Mat& tile) {
  requireGrey(image, "findTileAtAnyTurn", "image");
  requireGrey(tile, "findTileAtAnyTurn", "tile");
  TurnedPeak best;
  // Neither way round inside: nothing to correlate, and no reason to transform the image.
  if (!fitsInside(tile, image) && (tile.rows > image.cols || tile.cols > image.rows)) return best;
  const TileCorrelator correlator(image);
  // Turns 0 and 2 from one DFT of the tile, 1 and 3 (= 1 then half round) from another.
  for (int turns = 0; turns < 2; ++turns) {
    const cv::Mat tile_turned = turned(tile, turns);
    if (!fitsInside(tile_turned, image)) continue;
    const auto maps = correlator.ncc(tile_turned, true);
    const CorrelationPeak straight = peakOf(maps.first), half_round = peakOf(maps.second);
    if (straight.score > best.peak.score) best = {straight, turns};
    if (half_round.score > best.peak.score) best = {half_round, turns + 2};
  }
  return best;
}

namespace {

// A masked image's three spectra for masked NCC against other masked images (Padfield 2012):
// of the mask m, of the masked image m f and of its squares m f^2, as CCS-packed real DFTs at a
// size that holds every shift without wrapping. In float, less the masked mean: that changes no
// NCC and keeps the sums of squares small beside their differences, so scores agree with the
// direct sum to about 1e-7.
struct MaskedSpectra {
  cv::Mat mask, value, square;
};

MaskedSpectra maskedSpectra(const cv::Mat& image, const cv::Mat& mask, const cv::Size& padded) {
  cv::Mat m, v;
  cv::Mat(mask != 0).convertTo(m, CV_32F, 1.0 / 255.0);
  image.convertTo(v, CV_32F);
  const double mean = cv::countNonZero(mask) > 0 ? cv::mean(v, mask)[0] : 0.0;
  v = (v - mean).mul(m);
  const auto spectrum = [&padded](const cv::Mat& plane) {
    cv::Mat canvas = cv::Mat::zeros(padded, CV_32FC1), out;
    plane.copyTo(canvas(cv::Rect(0, 0, plane.cols, plane.rows)));
    cv::dft(canvas, out, 0, plane.rows);
    return out;
  };
  return {spectrum(m), spectrum(v), spectrum(v.mul(v))};
}

// corr(a, b)(d) = sum_p a(p) b(p - d) (conjugate) or conv(a, b)(s) = sum_p a(p) b(s - p), for
// every d (at index d mod the padded size) or s.
cv::Mat transform(const cv::Mat& spectrum_a, const cv::Mat& spectrum_b, bool conjugate) {
  cv::Mat product, out;
  cv::mulSpectrums(spectrum_a, spectrum_b, product, 0, conjugate);
  cv::idft(product, out, cv::DFT_SCALE | cv::DFT_REAL_OUTPUT);
  return out;
}

// The masked NCC of `moving` (w x h) against the fixed image at every shift with enough common
// texels, at its own turn (correlations) and half a turn further (convolutions: with R(q) =
// M(size - 1 - q), corr(F, R)(d) = conv(F, M)(d + size - 1)), so one set of the moving image's
// spectra serves two turns. `best` keeps the highest; `turns` is the moving image's own turn.
void bestOverlaps(const MaskedSpectra& fixed, const cv::Size& fixed_size,
                  const MaskedSpectra& moving, const cv::Size& moving_size, const cv::Size& padded,
                  double min_overlap, int turns, bool half_turn_too, TurnedPeak& best) {
  for (const bool half_turn : {false, true}) {
    if (half_turn && !half_turn_too) break;
    const bool conjugate = !half_turn;
    const cv::Mat n = transform(fixed.mask, moving.mask, conjugate);
    const cv::Mat sf = transform(fixed.value, moving.mask, conjugate);
    const cv::Mat sg = transform(fixed.mask, moving.value, conjugate);
    const cv::Mat sff = transform(fixed.square, moving.mask, conjugate);
    const cv::Mat sgg = transform(fixed.mask, moving.square, conjugate);
    const cv::Mat sfg = transform(fixed.value, moving.value, conjugate);
    // Shift d sits at d mod the padded size in a correlation, at d + size - 1 in a convolution.
    const auto index = [half_turn](int d, int extent, int size) {
      if (half_turn) return d + extent - 1;
      return d >= 0 ? d : d + size;
    };
    for (int y = -(moving_size.height - 1); y < fixed_size.height; ++y) {
      const int row = index(y, moving_size.height, padded.height);
      for (int x = -(moving_size.width - 1); x < fixed_size.width; ++x) {
        const int col = index(x, moving_size.width, padded.width);
        const double count = std::round(n.at<float>(row, col));
        if (count < std::max(2.0, min_overlap)) continue;
        const double mean_f = sf.at<float>(row, col), mean_g = sg.at<float>(row, col);
        const double var_f = sff.at<float>(row, col) - mean_f * mean_f / count;
        const double var_g = sgg.at<float>(row, col) - mean_g * mean_g / count;
        // Flat overlaps (no structure on one side) are not a placement.
        const double flat = count * kFlatStdDev * kFlatStdDev;
        if (var_f <= flat || var_g <= flat) continue;
        const double score =
            (sfg.at<float>(row, col) - mean_f * mean_g / count) / std::sqrt(var_f * var_g);
        if (score > best.peak.score)
          best = {{x, y, std::min(1.0, score)}, turns + (half_turn ? 2 : 0)};
      }
    }
  }
}

void requireMasks(const cv::Mat& fixed, const cv::Mat& fixed_mask, const cv::Mat& moving,
                  const cv::Mat& moving_mask, const char* function) {
  requireGrey(fixed, function, "fixed image");
  requireGrey(moving, function, "moving image");
  if (fixed_mask.size() != fixed.size() || moving_mask.size() != moving.size()) {
    throw core::Error(fmt::format("{}: each mask must have its image's size", function));
  }
}

}  // namespace

CorrelationPeak findOverlap(const cv::Mat& fixed, const cv::Mat& fixed_mask, const cv::Mat& moving,
                            const cv::Mat& moving_mask, double min_overlap) {
  requireMasks(fixed, fixed_mask, moving, moving_mask, "findOverlap");
  // Every shift from the moving image's bottom-right touching the fixed one's top-left to its
  // top-left touching the bottom-right, without wrapping onto another.
  const cv::Size padded(cv::getOptimalDFTSize(fixed.cols + moving.cols - 1),
                        cv::getOptimalDFTSize(fixed.rows + moving.rows - 1));
  const MaskedSpectra f = maskedSpectra(fixed, fixed_mask, padded);
  const MaskedSpectra g = maskedSpectra(moving, moving_mask, padded);
  TurnedPeak best;
  bestOverlaps(f, fixed.size(), g, moving.size(), padded, min_overlap, 0, false, best);
  return best.peak;
}

TurnedPeak findOverlapAtAnyTurn(const cv::Mat& fixed, const cv::Mat& fixed_mask,
                                const cv::Mat& moving, const cv::Mat& moving_mask,
                                double min_overlap) {
  requireMasks(fixed, fixed_mask, moving, moving_mask, "findOverlapAtAnyTurn");
  // One padded size for the moving image upright and on its side.
  const int reach = std::max(moving.cols, moving.rows) - 1;
  const cv::Size padded(cv::getOptimalDFTSize(fixed.cols + reach),
                        cv::getOptimalDFTSize(fixed.rows + reach));
  const MaskedSpectra f = maskedSpectra(fixed, fixed_mask, padded);
  TurnedPeak best;
  for (int turns = 0; turns < 2; ++turns) {
    const cv::Mat g = turned(moving, turns), g_mask = turned(moving_mask, turns);
    bestOverlaps(f, fixed.size(), maskedSpectra(g, g_mask, padded), g.size(), padded, min_overlap,
                 turns, true, best);
  }
  return best;
}

CorrelationPeak refineOverlap(const cv::Mat& fixed, const cv::Mat& fixed_mask,
                              const cv::Mat& moving, const cv::Mat& moving_mask,
                              const CorrelationPeak& start, int radius, double min_overlap) {
  requireGrey(fixed, "refineOverlap", "fixed image");
  requireGrey(moving, "refineOverlap", "moving image");
  CorrelationPeak best;
  for (int y = start.y - radius; y <= start.y + radius; ++y) {
    for (int x = start.x - radius; x <= start.x + radius; ++x) {
      // fixed(p) against moving(p - (x, y)) over the rows and columns both have.
      const int row0 = std::max(0, y), row1 = std::min(fixed.rows, y + moving.rows);
      const int col0 = std::max(0, x), col1 = std::min(fixed.cols, x + moving.cols);
      double count = 0, sf = 0, sg = 0, sff = 0, sgg = 0, sfg = 0;
      for (int r = row0; r < row1; ++r) {
        const auto* f = fixed.ptr<float>(r);
        const auto* g = moving.ptr<float>(r - y) - x;
        const auto* mf = fixed_mask.ptr<std::uint8_t>(r);
        const auto* mg = moving_mask.ptr<std::uint8_t>(r - y) - x;
        for (int c = col0; c < col1; ++c) {
          if (mf[c] == 0 || mg[c] == 0) continue;
          const double a = f[c], b = g[c];
          count += 1, sf += a, sg += b, sff += a * a, sgg += b * b, sfg += a * b;
        }
      }
      if (count < std::max(2.0, min_overlap)) continue;
      const double var_f = sff - sf * sf / count, var_g = sgg - sg * sg / count;
      const double flat = count * kFlatStdDev * kFlatStdDev;
      if (var_f <= flat || var_g <= flat) continue;
      const double score = (sfg - sf * sg / count) / std::sqrt(var_f * var_g);
      if (score > best.score) best = {x, y, std::min(1.0, score)};
    }
  }
  return best;
}

}  // namespace tessera::match
