// `tessera run --continue`: a map saved at the end of one run and continued by the next.
#include <cstdint>
#include <fstream>
#include <optional>
#include <set>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "support/test_data.h"
#include "tessera/core/error.h"
#include "tessera/drivers/oni/oni_source.h"
#include "tessera/eval/run_evaluation.h"
#include "tessera/fusion/map_keyframes.h"
#include "tessera/pipeline/run.h"

namespace tessera::pipeline {
namespace {

namespace fs = std::filesystem;

nlohmann::json readJson(const fs::path& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

std::set<int> patchIds(const fs::path& run_dir) {
  std::set<int> ids;
  const nlohmann::json patches = readJson(run_dir / "patches.json");
  for (const auto& patch : patches["patches"]) {
    ids.insert(patch["id"].get<int>());
  }
  return ids;
}

// The office's first 160 frames, then its last 160 continuing that map with no pose hint:
// the second session is found in the first one's map, its poses are in that frame (the first
// session started at the ground truth), and the merged map has one patch per plane.
TEST(ContinueMap, TwoSessionsOfTheOfficeEndWithOneMap) {
  const fs::path recording = test::sourceDir() / "recordings/office.oni";
  if (!fs::is_regular_file(recording)) {
    GTEST_SKIP() << recording << " is not rendered (TESSERA_RENDER_DEFAULT_RECORDING=ON)";
  }
  const fs::path out = test::freshTempDir();
  const RunConfig config = loadRunConfig(std::nullopt);
  {
    drivers::oni::OniSource source(recording);
    RunOptions options;
    options.out_dir = out;
    options.max_frames = 160;
    runPipeline(source, config, options);
  }
  const std::set<int> first_ids = patchIds(out);
  ASSERT_GE(first_ids.size(), 6u);
  ASSERT_TRUE(fs::is_regular_file(out / "map/session.json"));
  {
    drivers::oni::OniSource source(recording);
    RunOptions options;
    options.out_dir = out;
    options.skip_frames = 160;
    options.continue_map = true;
    const RunSummary summary = runPipeline(source, config, options);
    ASSERT_TRUE(summary.tracking.continued_map_found_at_frame.has_value());
    EXPECT_LE(*summary.tracking.continued_map_found_at_frame, 165);
    EXPECT_GT(summary.tracking.continued_map_keyframes, 10u);
    ASSERT_TRUE(summary.ate.has_value());
    EXPECT_LT(summary.ate->rmse_m, 0.01);
  }
  // Every surface the second session saw again grew a patch of the first: no new ids for
  // them, and no duplicate against the ground truth's planes.
  const std::set<int> ids = patchIds(out);
  for (int id : first_ids) EXPECT_EQ(ids.count(id), 1u) << "patch " << id << " lost";
  EXPECT_LE(ids.size(), first_ids.size() + 1);
  const nlohmann::json figures =
      eval::evaluateRun(out, fs::path(recording).replace_extension(".gt.json"));
  EXPECT_EQ(figures["duplicate_patches"], 0);
  EXPECT_GE(figures["plane_recall"].get<double>(), 0.8);
  EXPECT_GE(figures["plane_precision"].get<double>(), 0.99);
  EXPECT_EQ(readJson(out / "map/session.json")["sessions"], 2);
}

// The whole office, tracked: the keyframes loop closure found revisiting a kept keyframe's
// place are neither relocalised against nor saved; the saved map holds the others.
TEST(ContinueMap, TheSavedMapHoldsTheKeyframesLoopClosureKept) {
  const fs::path recording = test::sourceDir() / "recordings/office.oni";
  if (!fs::is_regular_file(recording)) {
    GTEST_SKIP() << recording << " is not rendered (TESSERA_RENDER_DEFAULT_RECORDING=ON)";
  }
  const fs::path out = test::freshTempDir();
  drivers::oni::OniSource source(recording);
  RunOptions options;
  options.out_dir = out;
  runPipeline(source, loadRunConfig(std::nullopt), options);
  const nlohmann::json report = readJson(out / "report.json");
  const auto made = report["keyframes_made"].get<std::size_t>();
  const auto covered = report["loop_keyframes_covered"].get<std::size_t>();
  EXPECT_EQ(report["keyframes"].get<std::size_t>(), made);
  EXPECT_GT(covered, 0u);
  EXPECT_EQ(report["relocalisation_keyframes"].get<std::size_t>(), made - covered);
  EXPECT_EQ(fusion::readMapKeyframes(out / "map/keyframes.bin").size(), made - covered);
}

// The state of every file in `dir` (name, size, write time), to show nothing changed.
std::map<std::string, std::pair<std::uintmax_t, fs::file_time_type>> filesOf(const fs::path& dir) {
  std::map<std::string, std::pair<std::uintmax_t, fs::file_time_type>> files;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (entry.is_regular_file()) {
      files[entry.path().string()] = {entry.file_size(), entry.last_write_time()};
    }
  }
  return files;
}

// The office's first `frames` frames into `out`.
void runOfficeStart(const fs::path& out, std::size_t frames, const RunConfig& config,
                    bool save_map = true) {
  drivers::oni::OniSource source(test::sourceDir() / "recordings/office.oni");
  RunOptions options;
  options.out_dir = out;
  options.max_frames = frames;
  options.save_map = save_map;
  runPipeline(source, config, options);
}

std::string continueError(const fs::path& out, std::optional<std::string> db = std::nullopt) {
  const fs::path recording = test::sourceDir() / "recordings/office.oni";
  drivers::oni::OniSource source(recording);
  RunOptions options;
  options.out_dir = out;
  options.max_frames = 5;
  options.continue_map = true;
  options.db = std::move(db);
  try {
    runPipeline(source, loadRunConfig(std::nullopt), options);
  } catch (const core::Error& e) {
    return e.what();
  }
  return "";
}

// A missing, cut or newer map is refused with one message naming the file, before anything
// in the folder is written.
TEST(ContinueMap, AMissingCorruptOrNewerMapIsRefusedAndNothingIsOverwritten) {
  const fs::path recording = test::sourceDir() / "recordings/office.oni";
  if (!fs::is_regular_file(recording)) {
    GTEST_SKIP() << recording << " is not rendered (TESSERA_RENDER_DEFAULT_RECORDING=ON)";
  }
  const fs::path out = test::freshTempDir();
  runOfficeStart(out, 40, loadRunConfig(std::nullopt), false);
  ASSERT_FALSE(fs::exists(out / "map"));
  EXPECT_NE(continueError(out).find("no saved map to continue"), std::string::npos);
  {
    // A checkpoint after every frame, while patches are committed beside it.
    RunConfig config = loadRunConfig(std::nullopt);
    config.pipeline.checkpoint_every_s = 1e-9;
    runOfficeStart(out, 40, config);
  }
  ASSERT_TRUE(fs::is_regular_file(out / "map/patch_map.bin"));
  // The map holds its own bitmap files, each of its binding's size (checkpoints taken while
  // newer versions were written).
  const nlohmann::json bitmaps = readJson(out / "map/bitmaps.json");
  int bound = 0;
  for (const auto& patch : bitmaps["patches"]) {
    if (!patch.contains("bitmap")) continue;
    const auto& binding = patch["bitmap"];
    const cv::Mat image = cv::imread((out / "map" / binding["image"].get<std::string>()).string(),
                                     cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(image.empty()) << binding["image"];
    EXPECT_EQ(image.cols, binding["width"].get<int>());
    EXPECT_EQ(image.rows, binding["height"].get<int>());
    ++bound;
  }
  EXPECT_GT(bound, 0);

  // Another texture database than the map's.
  auto before = filesOf(out);
  std::string error = continueError(out, (out / "other.db").string());
  EXPECT_NE(error.find("--db names another"), std::string::npos) << error;
  EXPECT_EQ(filesOf(out), before);

  // A count that does not fit in the file: refused before anything is allocated.
  const fs::path keyframes = out / "map/keyframes.bin";
  const fs::path keyframes_kept = out / "keyframes.bin.kept";
  fs::rename(keyframes, keyframes_kept);
  {
    std::ofstream file(keyframes, std::ios::binary);
    const std::uint32_t version = 1;
    const std::uint64_t count = 1U << 20U;
    file << "tessera-keyframes";
    file.write(reinterpret_cast<const char*>(&version), sizeof version);
    file.write(reinterpret_cast<const char*>(&count), sizeof count);
  }
  before = filesOf(out);
  error = continueError(out);
  EXPECT_NE(error.find("keyframes.bin: corrupt (a count of 1048576 items"), std::string::npos)
      << error;
  EXPECT_EQ(filesOf(out), before);
  fs::rename(keyframes_kept, keyframes);

  // Cut short.
  const fs::path patch_map = out / "map/patch_map.bin";
  fs::resize_file(patch_map, fs::file_size(patch_map) / 2);
  before = filesOf(out);
  error = continueError(out);
  EXPECT_NE(error.find("patch_map.bin: corrupt"), std::string::npos) << error;
  EXPECT_EQ(filesOf(out), before);

  // Written by a newer tessera.
  fs::resize_file(patch_map, 0);
  {
    std::ofstream file(out / "map/session.json");
    file << R"({"format": 99, "sessions": 1, "database": "x"})";
  }
  before = filesOf(out);
  error = continueError(out);
  EXPECT_NE(error.find("session.json: written by a newer tessera"), std::string::npos) << error;
  EXPECT_EQ(filesOf(out), before);
}

// A run killed between the two renames that swap a new map in leaves the earlier map as
// map.old: it is continued, and is the map again.
TEST(ContinueMap, ASwapCutOffBetweenItsRenamesContinuesTheEarlierMap) {
  const fs::path recording = test::sourceDir() / "recordings/office.oni";
  if (!fs::is_regular_file(recording)) {
    GTEST_SKIP() << recording << " is not rendered (TESSERA_RENDER_DEFAULT_RECORDING=ON)";
  }
  const fs::path out = test::freshTempDir();
  runOfficeStart(out, 40, loadRunConfig(std::nullopt));
  fs::rename(out / "map", out / "map.old");
  fs::create_directories(out / "map.saving");  // the new one, written whole but not swapped in
  EXPECT_EQ(continueError(out), "");
  EXPECT_TRUE(fs::is_regular_file(out / "map/session.json"));
  EXPECT_EQ(readJson(out / "map/session.json")["sessions"], 2);
  EXPECT_FALSE(fs::exists(out / "map.old"));
  EXPECT_FALSE(fs::exists(out / "map.saving"));
}

// A session that is never found in the map it continues maps in its own frame: the earlier
// patches stay as they were, not grown by regions placed in another frame. (Here the lookup is
// made to fail, and the session starts at the recording's true pose, where its regions would
// otherwise continue the earlier planes.)
TEST(ContinueMap, ASessionNotFoundInTheMapLeavesItsPatchesAsTheyWere) {
  const fs::path recording = test::sourceDir() / "recordings/office.oni";
  if (!fs::is_regular_file(recording)) {
    GTEST_SKIP() << recording << " is not rendered (TESSERA_RENDER_DEFAULT_RECORDING=ON)";
  }
  const fs::path out = test::freshTempDir();
  RunConfig config = loadRunConfig(std::nullopt);
  {
    drivers::oni::OniSource source(recording);
    RunOptions options;
    options.out_dir = out;
    options.max_frames = 100;
    runPipeline(source, config, options);
  }
  const nlohmann::json before = readJson(out / "patches.json");
  config.tracker.relocalisation_min_votes = 1'000'000;  // no keyframe is ever a candidate
  {
    drivers::oni::OniSource source(recording);
    RunOptions options;
    options.out_dir = out;
    options.skip_frames = 100;
    options.max_frames = 60;
    options.continue_map = true;
    const RunSummary summary = runPipeline(source, config, options);
    EXPECT_FALSE(summary.tracking.continued_map_found_at_frame.has_value());
  }
  const nlohmann::json after = readJson(out / "patches.json");
  std::map<int, nlohmann::json> now;
  for (const auto& patch : after["patches"]) now[patch["id"].get<int>()] = patch;
  ASSERT_FALSE(before["patches"].empty());
  for (const auto& patch : before["patches"]) {
    const int id = patch["id"].get<int>();
    ASSERT_EQ(now.count(id), 1u) << "patch " << id;
    EXPECT_EQ(now[id]["version"], patch["version"]) << "patch " << id;
    EXPECT_EQ(now[id]["area_m2"], patch["area_m2"]) << "patch " << id;
  }
  EXPECT_GT(after["patches"].size(), before["patches"].size());  // the session's own
  // The saved map is kept as the first session left it: a map in two frames is no map.
  const nlohmann::json session = readJson(out / "map/session.json");
  EXPECT_EQ(session["sessions"], 1);
  EXPECT_EQ(session["patches"], before["patches"].size());
}

}  // namespace
}  // namespace tessera::pipeline
