// The texture database on the default recording: what is reused, that it does not depend on the
// thread count, and that a second run of the same place reuses what the first stored.
#include <fstream>
#include <iterator>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <tuple>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "support/test_data.h"
#include "tessera/db/texture_store.h"
#include "tessera/drivers/oni/oni_source.h"
#include "tessera/eval/run_evaluation.h"
#include "tessera/pipeline/run.h"

namespace tessera::pipeline {
namespace {

namespace fs = std::filesystem;

const fs::path kRecording = test::sourceDir() / "recordings/office.oni";

// `live`, when given, gets the texture economy the monitor showed after the last commit.
RunSummary runOffice(const fs::path& out, int threads, std::optional<std::string> db = {},
                     reuse::Economy* live = nullptr) {
  drivers::oni::OniSource source(kRecording);
  MapMonitor monitor;
  RunOptions options;
  options.out_dir = out;
  options.threads = threads;
  options.poses = PoseSource::kGroundTruth;
  options.db = std::move(db);
  options.monitor = &monitor;
  RunSummary summary = runPipeline(source, loadRunConfig(std::nullopt), options);
  if (live != nullptr) *live = monitor.snapshot().commits.economy;
  return summary;
}

// (patch, version, layer, texture, reused) of every instance.
using Instances = std::set<std::tuple<int, int, int, std::int64_t, bool>>;
Instances instancesOf(const fs::path& db_path) {
  Instances instances;
  for (const db::TextureInstance& i : db::openSqliteStore(db_path, {false, true})->instances()) {
    instances.insert({i.patch_id, i.version, i.layer, i.texture_id, i.reused});
  }
  return instances;
}

std::string readText(const fs::path& path) {
  std::ifstream in(path);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// A TUM trajectory's lines (after its comments) in ascending time.
bool timestampsAscend(const fs::path& path) {
  std::ifstream in(path);
  double previous = -1.0;
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    const double t = std::stod(line);
    if (t <= previous) return false;
    previous = t;
  }
  return previous >= 0.0;
}

#define TESSERA_REQUIRE_OFFICE_FOR_REUSE()                                \
  if (!fs::is_regular_file(kRecording)) {                                 \
    GTEST_SKIP() << "recordings/office.oni not rendered (configure with " \
                    "TESSERA_RENDER_DEFAULT_RECORDING=ON)";               \
  }

// The office's two oak tables: the second table's top reuses the first's texture, turned by the
// half turn between their grids, and the ground truth finds no false match. The database holds
// the same textures and instances whether one thread or two ran.
TEST(TextureReuse, TheSecondTableReusesTheFirstAndOneOrTwoThreadsStoreTheSame) {
  TESSERA_REQUIRE_OFFICE_FOR_REUSE();
  const fs::path root = test::freshTempDir();
  const RunSummary one = runOffice(root / "one", 1);
  reuse::Economy live;
  const RunSummary two = runOffice(root / "two", 2, std::nullopt, &live);
  EXPECT_EQ(one.commits.textures_stored, two.commits.textures_stored);
  EXPECT_EQ(one.economy.reuses, two.economy.reuses);
  EXPECT_EQ(one.commits.patterns_stored, two.commits.patterns_stored);
  EXPECT_GE(two.commits.patterns_stored, 1u);  // the tiled floor, or a brick wall, as one cell
  EXPECT_EQ(one.commits.ccv_considered, two.commits.ccv_considered);
  EXPECT_EQ(one.commits.ccv_removed, two.commits.ccv_removed);
  EXPECT_EQ(instancesOf(root / "one/textures.db"), instancesOf(root / "two/textures.db"));
  // A patch finalized again leaves none of its older versions' textures behind: every texture
  // stored is used, and the report counts the ones removed.
  EXPECT_EQ(one.commits.textures_removed, two.commits.textures_removed);
  const auto stored = db::openSqliteStore(root / "two/textures.db", {false, true})->textures();
  EXPECT_EQ(stored.size(), two.commits.textures_stored - two.commits.textures_removed);
  for (const db::TextureSummary& texture : stored) EXPECT_GT(texture.uses, 0u) << texture.id;
  // Every stage saw the frames in the source's order, with one thread or two.
  EXPECT_EQ(readText(root / "one/trajectory.txt"), readText(root / "two/trajectory.txt"));
  EXPECT_TRUE(timestampsAscend(root / "two/trajectory.txt"));
  EXPECT_GE(two.economy.reuses, 1u);
  EXPECT_LT(two.economy.pixels_after, two.economy.pixels_before);
  // The live economy is the report's: after the last commit the two agree.
  EXPECT_EQ(live.pixels_before, two.economy.pixels_before);
  EXPECT_EQ(live.pixels_after, two.economy.pixels_after);
  EXPECT_EQ(live.textured_patches, two.economy.textured_patches);
  EXPECT_EQ(live.reuses, two.economy.reuses);
  EXPECT_EQ(live.overlays, two.economy.overlays);
  // The paper's table: the north brick wall matches the south wall's pattern; the second
  // table and the second plaster wall match stored (non-pattern) textures.
  EXPECT_GE(two.economy.patterns_matched, 1u);
  EXPECT_GE(two.economy.textures_matched, 2u);

  const nlohmann::json figures =
      eval::evaluateRun(root / "two", test::sourceDir() / "recordings/office.gt.json");
  EXPECT_EQ(figures["false_matches"], 0);
  std::map<std::string, std::int64_t> texture_of_plane;
  std::optional<bool> second_table_reused;
  for (const auto& patch : figures["textures"]) {
    const std::string plane = patch["plane"];
    texture_of_plane[plane] = patch["texture_id"].get<std::int64_t>();
    if (plane == "table_1.top" || plane == "table_2.top") {
      if (patch["reused"].get<bool>()) second_table_reused = true;
    }
  }
  ASSERT_TRUE(texture_of_plane.count("table_1.top") && texture_of_plane.count("table_2.top"));
  EXPECT_EQ(texture_of_plane["table_1.top"], texture_of_plane["table_2.top"]);
  EXPECT_TRUE(second_table_reused.value_or(false));
  for (const double psnr : two.economy.shown_psnrs_db) {  // reuses and patterns
    EXPECT_GE(psnr, loadRunConfig(std::nullopt).match.min_psnr_db);
  }

  // The north brick wall carries poster A: it reuses the south wall's pattern tile (their
  // grids turned a few degrees apart), with the poster (0.6 x 0.85 m) as an overlay whose box
  // holds it (the box is the texel grid's, turned against the poster), drawn as its own
  // object in the OBJ.
  ASSERT_TRUE(texture_of_plane.count("wall_north") && texture_of_plane.count("wall_south"));
  EXPECT_EQ(texture_of_plane["wall_north"], texture_of_plane["wall_south"]);
  EXPECT_EQ(one.economy.overlays, two.economy.overlays);
  std::optional<int> north_patch;
  for (const auto& patch : figures["textures"]) {
    if (patch["plane"] == "wall_north") north_patch = patch["patch"].get<int>();
  }
  ASSERT_TRUE(north_patch);
  std::ifstream patches_file(root / "two/patches.json");
  const nlohmann::json patches = nlohmann::json::parse(patches_file);
  bool poster = false;
  for (const auto& patch : patches["patches"]) {
    if (patch["id"] != *north_patch || patch["instance"].is_null()) continue;
    EXPECT_TRUE(patch["instance"]["reused"].get<bool>());
    const double texel_m = patch["texture"]["texel_m"];
    const double poster_w = 0.6 / texel_m, poster_h = 0.85 / texel_m;
    for (const auto& overlay : patch["instance"]["overlays"]) {
      const double w = overlay["width"], h = overlay["height"];
      poster |= w >= poster_w && h >= poster_h && w * h <= 1.6 * poster_w * poster_h;
    }
  }
  EXPECT_TRUE(poster);
  // The two plaster walls show the same plaster: the later one reuses the earlier one's
  // texture, with what differs (the blackboard, the posters' places) as overlays.
  ASSERT_TRUE(texture_of_plane.count("wall_west") && texture_of_plane.count("wall_east"));
  EXPECT_EQ(texture_of_plane["wall_west"], texture_of_plane["wall_east"]);
  EXPECT_GE(two.economy.overlays, 4u);
  const std::string text = readText(root / "two/patches.obj");
  EXPECT_NE(text.find(fmt::format("o patch_{}_v", *north_patch)), std::string::npos);
  EXPECT_NE(text.find("_overlay_1"), std::string::npos);
}

// Repeated runs in one place: the second run with the same database reuses at least 90 % of its
// patches' textures and grows the database by at most 10 %.
TEST(TextureReuse, ASecondRunWithTheSameDatabaseReusesWhatTheFirstStored) {
  TESSERA_REQUIRE_OFFICE_FOR_REUSE();
  const fs::path root = test::freshTempDir();
  const std::string db_path = (root / "office.db").string();
  runOffice(root / "first", 2, db_path);
  const std::size_t textures_after_first =
      db::openSqliteStore(db_path, {false, true})->stats().textures;
  const RunSummary second = runOffice(root / "second", 2, db_path);
  const std::size_t textures_after_second =
      db::openSqliteStore(db_path, {false, true})->stats().textures;
  ASSERT_GT(second.economy.textured_patches, 0u);
  EXPECT_GE(static_cast<double>(second.economy.reuses),
            0.9 * static_cast<double>(second.economy.textured_patches));
  EXPECT_LE(static_cast<double>(textures_after_second),
            1.1 * static_cast<double>(textures_after_first));
  EXPECT_EQ(db::openSqliteStore(db_path, {false, true})->runs().size(), 2u);
}

}  // namespace
}  // namespace tessera::pipeline
