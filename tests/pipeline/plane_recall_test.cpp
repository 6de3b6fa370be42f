#include <optional>
#include <set>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "support/test_data.h"
#include "tessera/drivers/oni/oni_source.h"
#include "tessera/eval/run_evaluation.h"
#include "tessera/pipeline/run.h"

namespace tessera::pipeline {
namespace {

namespace fs = std::filesystem;

// Runs the default recording and evaluates its planes; nothing when it was not rendered.
std::optional<nlohmann::json> planeFigures(PoseSource poses) {
  const fs::path recording = test::sourceDir() / "recordings/office.oni";
  if (!fs::is_regular_file(recording)) return std::nullopt;
  drivers::oni::OniSource source(recording);
  RunOptions options;
  options.out_dir = test::freshTempDir();
  options.poses = poses;
  const RunSummary summary = runPipeline(source, loadRunConfig(std::nullopt), options);
  EXPECT_EQ(summary.stream.frames, 320u);
  return eval::evaluateRun(options.out_dir, test::sourceDir() / "recordings/office.gt.json");
}

void expectTheRoomsPlanes(const nlohmann::json& figures) {
  EXPECT_GE(figures["plane_recall"].get<double>(), 0.75);
  EXPECT_GE(figures["plane_precision"].get<double>(), 0.95);
  EXPECT_LE(figures["plane_normal_error_deg_max"].get<double>(), 2.0);
  EXPECT_LE(figures["plane_offset_error_m_max"].get<double>(), 0.01);
  EXPECT_GE(figures["plane_iou_min"].get<double>(), 0.8);
  // The big planes are all there: floor, four walls, both table tops.
  const std::set<std::string> big = {"floor",     "wall_south",  "wall_north", "wall_west",
                                     "wall_east", "table_1.top", "table_2.top"};
  std::size_t big_found = 0;
  for (const auto& plane : figures["planes"]) {
    if (big.count(plane["id"]) > 0 && plane["found"].get<bool>()) ++big_found;
  }
  EXPECT_EQ(big_found, big.size());
}

// The bitmaps against the true textures (tessera eval's ground-truth PSNR), and against the same
// texels coloured from the TSDF's voxel colours.
void expectSharpTextures(const nlohmann::json& figures, double min_mean_db) {
  EXPECT_GE(figures["gt_psnr_mean"].get<double>(), min_mean_db);
  EXPECT_GE(figures["gt_psnr_registered_mean"].get<double>(),
            figures["gt_psnr_mean"].get<double>());
  EXPECT_GE(figures["gt_psnr_mean"].get<double>(),
            figures["gt_psnr_tsdf_baseline_mean"].get<double>() + 3.0);
  EXPECT_GE(figures["textures"].size(), 7u);
  for (const auto& texture : figures["textures"]) {
    EXPECT_GE(texture["psnr_db"].get<double>(), 20.0) << texture["plane"];
  }
}

#define TESSERA_REQUIRE_DEFAULT_RECORDING(figures)                                          \
  if (!(figures)) {                                                                        \
    GTEST_SKIP() << "recordings/office.oni not rendered (configure with "                  \
                    "TESSERA_RENDER_DEFAULT_RECORDING=ON)";                                \
  }

// At the recording's true poses the figures measure plane extraction alone. Measured: recall
// 0.8 (8 of the 10 planes seen over 0.25 m^2; the cabinet's top and left side, seen only at
// grazing angles, are missed), precision 1.0; texture PSNR 30.9 dB (TSDF colours 22.2 dB).
TEST(PlaneRecall, DefaultRecordingAtTruePosesFindsTheRoomsPlanesWithoutDuplicates) {
  const auto figures = planeFigures(PoseSource::kGroundTruth);
  TESSERA_REQUIRE_DEFAULT_RECORDING(figures);
  expectTheRoomsPlanes(*figures);
  expectSharpTextures(*figures, 29.0);
}

// With tracked poses (8 mm ATE) the drift correction against the patches keeps them within the
// same bounds; without it the table tops land 1.4 to 1.6 cm off (recall 0.5, precision 0.63).
// Texture PSNR with tracked poses: 27.3 dB as placed (28.8 registered), the target being 25.
TEST(PlaneRecall, DefaultRecordingAtTrackedPosesMeetsTheSameBounds) {
  const auto figures = planeFigures(PoseSource::kTrack);
  TESSERA_REQUIRE_DEFAULT_RECORDING(figures);
  expectTheRoomsPlanes(*figures);
  expectSharpTextures(*figures, 25.0);
}

}  // namespace
}  // namespace tessera::pipeline
