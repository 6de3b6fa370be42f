#pragma once
// Shared pieces of the texture store tests: a temporary folder per test, seeded synthetic
// textures, and raw file and SQLite access to check what the store left on disk.
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <unistd.h>

#include "tessera/core/error.h"
#include "tessera/db/texture_store.h"

namespace tessera::db::test {

// A fresh folder under the system temporary folder, removed with everything in it.
class TempFolder {
 public:
  TempFolder() {
    static std::atomic<int> counter{0};
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    const std::string test = info != nullptr ? info->name() : "none";
    path_ = std::filesystem::temp_directory_path() /
            ("tessera_db_" + test + "_" + std::to_string(::getpid()) + "_" +
             std::to_string(counter++) + "_" + std::to_string(std::random_device{}()));
    std::filesystem::create_directories(path_);
  }
  ~TempFolder() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempFolder(const TempFolder&) = delete;
  TempFolder& operator=(const TempFolder&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

constexpr std::size_t kCcvSize = 48;

// A texture with every field set from `seed`: random pixels, a mask with holes (whose pixels
// keep their colour), a CCV, SIFT-like keypoints and float descriptors.
inline TextureRecord makeTexture(std::uint32_t seed, int width = 32, int height = 24) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> byte(0, 255);
  std::uniform_real_distribution<float> real(0.0f, 1.0f);
  TextureRecord t;
  t.rgb.create(height, width, CV_8UC3);
  t.mask.create(height, width, CV_8UC1);
  for (int r = 0; r < height; ++r) {
    for (int c = 0; c < width; ++c) {
      t.rgb.at<cv::Vec3b>(r, c) =
          cv::Vec3b(static_cast<std::uint8_t>(byte(rng)), static_cast<std::uint8_t>(byte(rng)),
                    static_cast<std::uint8_t>(byte(rng)));
      t.mask.at<std::uint8_t>(r, c) = (r + c) % 7 == 0 ? 0 : 255;
    }
  }
  t.texel_m = 0.004;
  for (std::size_t i = 0; i < kCcvSize; ++i) t.ccv.push_back(real(rng));
  t.feature_kind = "sift";
  for (int i = 0; i < 4; ++i) {
    t.keypoints.emplace_back(real(rng) * static_cast<float>(width),
                             real(rng) * static_cast<float>(height), 1.6f + real(rng),
                             360.0f * real(rng), real(rng), i % 3, i - 1);
  }
  t.descriptors.create(4, 128, CV_32F);
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 128; ++c) t.descriptors.at<float>(r, c) = real(rng);
  }
  return t;
}

// The message of the core::Error that `fn` throws; fails the test when it throws none.
template <typename Fn>
std::string errorOf(Fn fn) {
  try {
    fn();
  } catch (const core::Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "expected a core::Error";
  return "";
}

inline std::string fileContents(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

inline std::vector<std::string> folderListing(const std::filesystem::path& folder) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    names.push_back(entry.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

// Runs `sql` on the file through SQLite directly (not through the store).
inline void rawExec(const std::filesystem::path& path, const std::string& sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  char* error = nullptr;
  const int rc = sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &error);
  EXPECT_EQ(rc, SQLITE_OK) << (error != nullptr ? error : "");
  sqlite3_free(error);
  sqlite3_close(db);
}

// The first column of the first row of `sql`, as text.
inline std::string rawQuery(const std::filesystem::path& path, const std::string& sql) {
  sqlite3* db = nullptr;
  std::string result = "<error>";
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READWRITE, nullptr) == SQLITE_OK) {
    sqlite3_stmt* stmt = nullptr;
    if (sqlite3_prepare_v2(db, sql.c_str(), -1, &stmt, nullptr) == SQLITE_OK &&
        sqlite3_step(stmt) == SQLITE_ROW) {
      const unsigned char* text = sqlite3_column_text(stmt, 0);
      result = text != nullptr ? reinterpret_cast<const char*>(text) : "<null>";
    }
    sqlite3_finalize(stmt);
  }
  sqlite3_close(db);
  return result;
}

// A run's worth of commits: new textures, a reuse of the same pixels, a newer version with an
// overlay layer, a late older version, a retired patch.
inline void commitRun(TextureStore& store) {
  const std::int64_t run = store.beginRun("recordings/office.oni");
  Commit first;
  first.textures = {makeTexture(1), makeTexture(2, 40, 20)};
  first.textures[1].kind = TextureKind::kPattern;
  first.textures[1].lattice = Lattice{{8.0, 0.0}, {0.5, 7.25}};
  for (auto& t : first.textures) t.run_id = run;
  for (int patch : {1, 2}) {
    TextureInstance i;
    i.run_id = run;
    i.patch_id = patch;
    i.version = 1;
    i.texture_id = -patch;
    i.transform = core::Similarity2::fromAngleScale(0.1 * patch, 1.0, 2.0, -3.0);
    first.instances.push_back(i);
  }
  store.commit(first);
  Commit second;  // the same pixels again (stored once), patch 1 at version 2 with an overlay
  second.textures = {makeTexture(1), makeTexture(3, 16, 16)};
  TextureInstance base;
  base.run_id = run;
  base.patch_id = 1;
  base.version = 2;
  base.texture_id = -1;
  base.reused = true;
  base.psnr_db = 31.5;
  TextureInstance overlay = base;
  overlay.layer = 1;
  overlay.texture_id = -2;
  overlay.psnr_db.reset();
  second.instances = {base, overlay};
  store.commit(second);
  Commit late;  // version 1 of patch 1 arriving after version 2: ignored
  TextureInstance old = base;
  old.version = 1;
  old.texture_id = 1;
  late.instances = {old};
  store.commit(late);
  Commit retire;
  retire.retired = {{run, 2}};
  store.commit(retire);
  store.finishRun(run);
}

// TextureStore::removeUnused, on either store: of the textures offered, only those the run
// stored and no instance uses go; imported ones, another run's and used ones stay.
inline void expectOnlyTheRunsUnusedTexturesAreRemoved(TextureStore& store) {
  const std::int64_t yesterday = store.beginRun("yesterday");
  const std::int64_t today = store.beginRun("today");
  const auto instance = [&](int patch, int version, int layer, std::int64_t texture_id) {
    TextureInstance i;
    i.run_id = today;
    i.patch_id = patch;
    i.version = version;
    i.layer = layer;
    i.texture_id = texture_id;
    return i;
  };
  Commit first;  // patch 2 version 1 (a base and an overlay), patch 3 sharing the overlay
  first.textures = {makeTexture(61), makeTexture(62), makeTexture(63), makeTexture(64)};
  first.textures[0].run_id = today;      // patch 2's old base
  first.textures[1].run_id = today;      // the shared overlay
  first.textures[2].run_id = 0;          // imported, used by nothing
  first.textures[3].run_id = yesterday;  // another run's, used by nothing
  first.instances = {instance(2, 1, 0, -1), instance(2, 1, 1, -2), instance(3, 1, 0, -2)};
  const std::vector<std::int64_t> ids = store.commit(first);
  Commit second;  // patch 2 version 2: a new base, no overlay
  second.textures = {makeTexture(65)};
  second.textures[0].run_id = today;
  second.instances = {instance(2, 2, 0, -1)};
  const std::int64_t new_base = store.commit(second).at(0);

  const std::int64_t unknown = new_base + 1000;
  const std::vector<std::int64_t> offered = {ids[2], ids[3], new_base, ids[1],
                                             ids[0], ids[0], unknown};
  EXPECT_EQ(store.removeUnused(today, offered), std::vector<std::int64_t>{ids[0]});
  EXPECT_FALSE(store.texture(ids[0]).has_value());
  for (const std::int64_t kept : {ids[1], ids[2], ids[3], new_base}) {
    EXPECT_TRUE(store.texture(kept).has_value()) << "texture " << kept;
  }
  EXPECT_FALSE(store.findByContentKey(contentKey(first.textures[0].rgb, first.textures[0].mask)));
  EXPECT_TRUE(store.removeUnused(today, offered).empty());       // nothing more to remove
  EXPECT_TRUE(store.removeUnused(yesterday, {ids[1]}).empty());  // not that run's
  Commit retire;  // patch 3 leaves: the overlay is used by nothing now
  retire.retired = {{today, 3}};
  store.commit(retire);
  EXPECT_EQ(store.removeUnused(today, {ids[1]}), std::vector<std::int64_t>{ids[1]});
  EXPECT_EQ(store.stats().textures, 3u);  // imported, yesterday's, patch 2's base
  // The same pixels stored again get a new texture.
  Commit again;
  again.textures = {first.textures[0]};
  EXPECT_GT(store.commit(again).at(0), ids[0]);
}

using InstanceKey = std::tuple<std::int64_t, int, int, int, std::int64_t, bool>;
inline std::set<InstanceKey> keysOf(const std::vector<TextureInstance>& instances) {
  std::set<InstanceKey> keys;
  for (const TextureInstance& i : instances) {
    keys.insert({i.run_id, i.patch_id, i.version, i.layer, i.texture_id, i.reused});
  }
  return keys;
}

}  // namespace tessera::db::test
