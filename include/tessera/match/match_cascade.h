#pragma once
// The matching cascade, cheapest first: the CCV prefilter removes stored textures whose colour
// coherence is too far from the new bitmap's; pattern textures left are looked for by
// normalised cross-correlation (at four quarter turns, since two patches' grids may be turned
// against each other), single textures by features and a RANSAC similarity. Every transform a
// stage proposes is verified by fidelity: the stored texture rendered through it onto the new
// patch's grid must reach min_psnr_db over its mask and cover min_coverage of it. The first
// candidate, in CCV order, that passes is the match; else there is none.
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "tessera/core/lattice2.h"
#include "tessera/core/similarity2.h"
#include "tessera/match/ccv.h"
#include "tessera/match/ccv_index.h"
#include "tessera/match/feature_matcher.h"
#include "tessera/match/fidelity.h"

namespace tessera::match {

struct MatchConfig {
  // false: every bitmap is stored as its own texture, undescribed and unmatched (to measure
  // what matching costs, or to build a map without reuse).
  bool enabled = true;
  CcvConfig ccv;
  FeatureConfig features;
  double ccv_max_distance = 0.6;   // the prefilter: candidates farther than this are removed
  std::size_t max_candidates = 4;  // at most this many, nearest first, go on to NCC/features
  double ncc_min_score = 0.5;      // a pattern tile must correlate at least this well
  double min_psnr_db = 28.0;       // fidelity of an accepted reuse
  double min_coverage = 0.85;      // share of the patch mask a single texture must cover
  // Bitmaps longer than this (pixels) are described (CCV, features) at this size: a wall's
  // 1000-texel bitmap costs 4 times less, and keypoints are scaled back to full size.
  int describe_max_px = 640;
  // Stored textures the matcher keeps described in memory, least recently used out first
  // (they are read back from the database when needed again): memory stays bounded as the
  // database grows.
  double catalog_cache_mb = 256.0;
  // Run the cascade ahead, on the describing threads, so that the serial commit only verifies
  // the candidates that changed since (the same decisions; the commit stage's time per patch
  // halves, at the cost of verifying again what changed in between).
  bool precheck = true;

  // The one rule for showing a patch through pixels other than its own (a reuse, a pattern, a
  // base with overlays): at least min_psnr_db over at least min_coverage of its mask.
  bool accepts(const Fidelity& fidelity) const { return refusal(fidelity).empty(); }
  // Why `fidelity` falls short of that rule, or "" when it does not.
  std::string refusal(const Fidelity& fidelity) const;
};

// A bitmap as the cascade sees it, computed once per new bitmap (and stored with a texture).
struct TextureDescription {
  cv::Mat rgb;   // CV_8UC3
  cv::Mat mask;  // CV_8UC1, 255 = valid
  Ccv ccv;
  Features features;
};
TextureDescription describeTexture(const cv::Mat& rgb, const cv::Mat& mask,
                                   const MatchConfig& config);
// The same without features (their detection is most of the cost): for a bitmap that is looked
// up by its CCV and compared pixel by pixel only.
TextureDescription describeColours(const cv::Mat& rgb, const cv::Mat& mask,
                                   const MatchConfig& config);

struct StoredTexture {
  std::int64_t id = 0;
  bool pattern = false;  // a tile that repeats
  // Singles: the texture itself. Patterns: a swatch of the pattern in its texture frame (one
  // cell's bounding box, the NCC template; its CCV from a larger swatch), whose pixel (0, 0)
  // is frame point `swatch_origin`.
  TextureDescription description;
  // Patterns: one cell of `lattice` (core::Lattice2) in the texture frame, as stored.
  core::Lattice2 lattice;
  cv::Mat tile_rgb, tile_mask;
  Eigen::Vector2d swatch_origin = Eigen::Vector2d::Zero();

  // The stored image and its size in pixels (the tile for a pattern).
  const cv::Mat& storedRgb() const { return pattern ? tile_rgb : description.rgb; }
  const cv::Mat& storedMask() const { return pattern ? tile_mask : description.mask; }
};

// A pattern texture from its tile and lattice: the swatch and its description (CCV only).
std::shared_ptr<StoredTexture> patternTexture(std::int64_t id, const cv::Mat& tile_rgb,
                                              const cv::Mat& tile_mask,
                                              const core::Lattice2& lattice,
                                              const MatchConfig& config);

// A stored texture rendered through `patch_to_texture` onto a width x height patch grid.
Rendered renderStored(const StoredTexture& stored, const core::Similarity2& patch_to_texture,
                      int width, int height);

// `patch_to_texture` (a single texture's, not a pattern's) refined by direct alignment of grey
// levels: the stored texture rendered onto the patch's grid is aligned with the patch's bitmap
// (OpenCV's ECC, an affine warp whose nearest similarity is kept), and that small correction
// goes first. Nothing when the alignment does not converge. `rendered`, when given, is that
// render already made (renderStored at `patch_to_texture` and the query's size).
std::optional<core::Similarity2> refinedByEcc(const TextureDescription& query,
                                              const StoredTexture& stored,
                                              const core::Similarity2& patch_to_texture,
                                              const Rendered* rendered = nullptr);

// Where candidates come from: the database through its CCV index, or a list in memory.
class TextureCatalog {
 public:
  virtual ~TextureCatalog() = default;
  // Textures the prefilter considers.
  virtual std::size_t size() const = 0;
  // At most k textures within max_distance of `ccv`, nearest first (ties: lower id first).
  virtual std::vector<CcvNeighbour> nearest(const std::vector<float>& ccv, double max_distance,
                                            std::size_t k) const = 0;
  // A texture the prefilter named (nothing if it is gone).
  virtual std::shared_ptr<const StoredTexture> load(std::int64_t id) const = 0;
};

// A catalog held in memory: tests, benches, `tessera match`, and the commit stage's re-check.
class MemoryCatalog : public TextureCatalog {
 public:
  explicit MemoryCatalog(const CcvConfig& ccv = {});
  void add(std::shared_ptr<const StoredTexture> texture);
  std::size_t size() const override { return textures_.size(); }
  std::vector<CcvNeighbour> nearest(const std::vector<float>& ccv, double max_distance,
                                    std::size_t k) const override;
  std::shared_ptr<const StoredTexture> load(std::int64_t id) const override;

 private:
  CcvIndex index_;
  std::vector<std::shared_ptr<const StoredTexture>> textures_;  // ascending id
};

// How one candidate fared.
struct CandidateVerdict {
  std::int64_t id = 0;
  double ccv_distance = 0.0;
  std::string method;  // "ncc" or "features"
  bool accepted = false;
  std::optional<core::Similarity2> transform;  // new patch texel -> stored texture pixel
  double psnr_db = 0.0, coverage = 0.0;
  std::string reason;  // why it was refused
};

struct MatchDecision {
  std::size_t considered = 0;              // textures the prefilter looked at
  std::size_t passed_ccv = 0;              // ... and let through
  std::vector<CandidateVerdict> verdicts;  // in CCV order, up to the accepted one
  std::optional<CandidateVerdict> match;   // the accepted one
  double ms = 0.0;
};

// Verdicts worked out ahead of the serial commit (MatchCascade::precheck, on the describing
// threads), each with the stored texture it was reached against.
struct PrecheckedVerdicts {
  std::vector<std::pair<std::weak_ptr<const StoredTexture>, CandidateVerdict>> verdicts;
  double ms = 0.0;

  // The verdict reached against exactly `stored` (the same object: an id alone could name a
  // texture stored after another was removed), or null.
  const CandidateVerdict* find(const StoredTexture& stored) const;
};

class MatchCascade {
 public:
  explicit MatchCascade(const MatchConfig& config = {}) : config_(config) {}
  const MatchConfig& config() const { return config_; }

  // Runs the cascade for a new bitmap against the catalog. Thread-safe. A candidate `prechecked`
  // holds a verdict for, reached against the very texture the catalog gives now, takes that
  // verdict instead of being verified again: the decision is the same as without it.
  MatchDecision match(const TextureDescription& query, const TextureCatalog& catalog,
                      const PrecheckedVerdicts* prechecked = nullptr) const;
  // The cascade's verifications against the catalog as it is now, for match() to take later
  // when the catalog has changed little. Thread-safe, given a thread-safe catalog.
  PrecheckedVerdicts precheck(const TextureDescription& query, const TextureCatalog& catalog) const;
  // Verifies one candidate (NCC or features, then fidelity).
  CandidateVerdict tryCandidate(const TextureDescription& query, const StoredTexture& stored,
                                double ccv_distance) const;

 private:
  std::optional<core::Similarity2> findPattern(const TextureDescription& query,
                                               const StoredTexture& stored,
                                               CandidateVerdict& verdict) const;
  // The candidates in CCV order up to the first accepted; `seen`, when given, gets each
  // verdict with the texture it was reached against.
  MatchDecision run(const TextureDescription& query, const TextureCatalog& catalog,
                    const PrecheckedVerdicts* prechecked, PrecheckedVerdicts* seen) const;

  MatchConfig config_;
};

}  // namespace tessera::match
