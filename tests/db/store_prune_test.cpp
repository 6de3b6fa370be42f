// db prune: a database an older build left with superseded textures loses exactly those.
#include "tessera/db/store_prune.h"

#include <gtest/gtest.h>

#include "db/store_test_support.h"

namespace tessera::db::test {
namespace {

TEST(StorePrune, RemovesTheUnusedTexturesOfFinishedRunsOnly) {
  TempFolder dir;
  auto store = openSqliteStore(dir / "textures.db");
  // What builds before removeUnused left: each version of a patch stored a texture, and only
  // the newest is used. The running run's and the imported ones must stay.
  const std::int64_t finished = store->beginRun("yesterday");
  const std::int64_t running = store->beginRun("now");
  const auto versions = [&](std::int64_t run, std::uint32_t seed) {
    std::vector<std::int64_t> ids;
    for (int version = 1; version <= 3; ++version) {
      Commit commit;
      commit.textures = {makeTexture(seed + static_cast<std::uint32_t>(version))};
      commit.textures[0].run_id = run;
      TextureInstance instance;
      instance.run_id = run;
      instance.patch_id = 7;
      instance.version = version;
      instance.texture_id = -1;
      commit.instances = {instance};
      ids.push_back(store->commit(commit).at(0));
    }
    return ids;
  };
  const std::vector<std::int64_t> old_run = versions(finished, 100);
  const std::vector<std::int64_t> new_run = versions(running, 200);
  Commit imported;
  imported.textures = {makeTexture(300)};
  const std::int64_t imported_id = store->commit(imported).at(0);
  store->finishRun(finished);

  const PruneReport report = pruneUnused(*store);
  EXPECT_EQ(report.removed, 2u);
  EXPECT_GT(report.png_bytes, 0u);
  EXPECT_EQ(report.kept_unfinished, 2u);
  EXPECT_EQ(report.textures_left, 5u);
  EXPECT_FALSE(store->texture(old_run[0]));
  EXPECT_FALSE(store->texture(old_run[1]));
  for (const std::int64_t kept : {old_run[2], new_run[0], new_run[1], new_run[2], imported_id}) {
    EXPECT_TRUE(store->texture(kept)) << kept;
  }
  EXPECT_EQ(pruneUnused(*store).removed, 0u);  // again: nothing
}

}  // namespace
}  // namespace tessera::db::test
