#pragma once
// What the texture database holds: textures (pixels, kind, CCV, features, lattice), instances
// (patch -> texture through a similarity, with its fidelity) and runs.
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>
#include <opencv2/core/types.hpp>

#include "tessera/core/lattice2.h"
#include "tessera/core/similarity2.h"

namespace tessera::db {

enum class TextureKind { kSingle, kPattern };
const char* kindName(TextureKind kind);  // "single" | "pattern"

// A pattern's period vectors in its texture frame (see core::Lattice2): the stored image is
// one cell. For stripes (periodic in one direction) v2 runs along the stripes.
using Lattice = core::Lattice2;

struct TextureRecord {
  std::int64_t id = 0;  // assigned by the store on commit
  TextureKind kind = TextureKind::kSingle;
  cv::Mat rgb;               // CV_8UC3, R G B order
  cv::Mat mask;              // CV_8UC1, 255 = valid texel (kept as the PNG's alpha)
  double texel_m = 0.0;      // 0 when unknown (imported images)
  std::vector<float> ccv;    // match::Ccv::values
  std::string feature_kind;  // "sift", "orb", "akaze" or "" (none)
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;             // one row per keypoint
  std::optional<Lattice> lattice;  // patterns only
  std::string content_key;         // contentKey(rgb, mask): the same pixels are stored once
  std::int64_t run_id = 0;         // the run that stored it; 0 when imported
  int source_patch = -1;           // the patch it was cut from, -1 when imported
  std::string name;                // an imported file's name, or "" for a patch's bitmap
};

// A short hash of the pixels and mask (hex), equal for equal images.
std::string contentKey(const cv::Mat& rgb, const cv::Mat& mask);

struct TextureSummary {
  std::int64_t id = 0;
  TextureKind kind = TextureKind::kSingle;
  int width = 0, height = 0;
  std::int64_t run_id = 0;
  int source_patch = -1;
  std::string name;
  std::size_t uses = 0;       // instances (of any layer) that use it, over every run
  std::size_t png_bytes = 0;  // its stored (compressed) size
};

// A patch's texture: patch texel (col, row) -> texture pixel through `transform`. Layer 0
// covers the whole patch; layers 1, 2, ... are overlays (a poster on a brick wall) drawn on
// top of it, each over the texels that map into its texture's valid pixels.
struct TextureInstance {
  std::int64_t run_id = 0;
  int patch_id = 0;
  int version = 0;
  int layer = 0;
  std::int64_t texture_id = 0;
  core::Similarity2 transform;
  std::optional<double> psnr_db;  // fidelity of a reuse; nothing when the patch stored its own
  bool reused = false;            // the texture existed before this patch
};

struct RunRecord {
  std::int64_t id = 0;
  std::string started_utc;  // ISO 8601
  std::string source;
  bool finished = false;
};

struct StoreStats {
  int schema_version = 0;
  std::size_t textures = 0, patterns = 0, instances = 0, runs = 0;
  std::size_t texture_pixels = 0;  // sum of width x height
  std::size_t file_bytes = 0;      // the database on disk
};

}  // namespace tessera::db
