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

using InstanceKey = std::tuple<std::int64_t, int, int, int, std::int64_t, bool>;
inline std::set<InstanceKey> keysOf(const std::vector<TextureInstance>& instances) {
  std::set<InstanceKey> keys;
  for (const TextureInstance& i : instances) {
    keys.insert({i.run_id, i.patch_id, i.version, i.layer, i.texture_id, i.reused});
  }
  return keys;
}

}  // namespace tessera::db::test
