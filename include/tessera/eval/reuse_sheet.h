#pragma once
// What the map shows for its reuses, to look at: RUN_DIR/reuse_sheet.png puts each reusing
// patch's own bitmap beside the texture the map shows in its place and their difference.
// Needs no ground truth, so `tessera eval` writes it for every run.
#include <cstdint>
#include <filesystem>
#include <optional>

#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>

#include "tessera/core/similarity2.h"

namespace tessera::eval {

// The database texture a patch shows in the map (its patches.json "instance"), rendered through
// the instance's transform onto the patch's own texel grid ("texture": width x height).
struct InstanceRender {
  std::int64_t texture_id = 0;
  core::Similarity2 transform;  // patch texel centre -> texture pixel centre
  bool reused = false;
  bool tiled = false;
  std::optional<double> psnr_db;  // as the run recorded it
  cv::Mat rgb;                    // CV_8UC3, black where not covered
  cv::Mat covered;                // CV_8UC1, 255 where the texture gave a colour
};

// Nothing when the patch has no instance (or no texture grid). Throws core::Error naming the
// image (relative paths start at run_dir) when it is missing or not an RGBA PNG.
std::optional<InstanceRender> renderInstance(const nlohmann::json& patch,
                                             const std::filesystem::path& run_dir);

struct ReuseSheetOptions {
  int row_height_px = 180;       // each panel is scaled to this height, keeping its aspect...
  int max_panel_width_px = 720;  // ...unless that makes it wider than this
  int label_height_px = 28;      // the text line above each row
  int gap_px = 8;                // between panels and around the sheet
  int checker_px = 8;            // side of the checkerboard squares shown where a panel is empty
  double difference_gain = 4.0;  // the third panel: gain x |own - reused|
};

// Writes RUN_DIR/reuse_sheet.png, one row per reuse in RUN_DIR/patches.json (an instance with
// "reused": true), in the order of the file: the patch's own bitmap | the reused texture
// rendered onto the patch's grid | difference_gain x the absolute difference (where both have a
// colour), under the label "patch P -> texture T  PSNR x dB  angle a deg  scale s" (PSNR of the
// two panels over the texels both cover; angle and scale of the patch-to-texture transform).
// Row r's label starts at y = gap + r * (label + row height + gap). With no reuse there is no
// sheet (an older one is removed) and an info line says so; likewise without patches.json.
// Returns the number of rows.
// Throws core::Error naming a file that is missing, malformed or cannot be written.
int writeReuseSheet(const std::filesystem::path& run_dir, const ReuseSheetOptions& options = {});

}  // namespace tessera::eval
