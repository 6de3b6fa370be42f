// copyStore between two SQLite databases: runs, textures and instances arrive with their ids
// mapped, pixels the destination already has are not stored twice, and a second copy adds
// nothing. (PostgreSQL to SQLite and back: postgres_store_test.cpp.)
#include <map>

#include "db/store_test_support.h"
#include "tessera/db/store_copy.h"

namespace tessera::db {
namespace {

using test::commitRun;
using test::makeTexture;
using test::TempFolder;

// Instances by content: (patch, version, layer, reused, the texture's content key).
std::set<std::tuple<int, int, int, bool, std::string>> instancesByContent(
    const TextureStore& store) {
  std::set<std::tuple<int, int, int, bool, std::string>> out;
  for (const TextureInstance& i : store.instances()) {
    out.insert({i.patch_id, i.version, i.layer, i.reused, store.texture(i.texture_id)->content_key});
  }
  return out;
}

TEST(StoreCopy, CopiesRunsTexturesAndInstancesAndAddsNothingTheSecondTime) {
  TempFolder dir;
  const auto from = openSqliteStore(dir / "robot.db");
  commitRun(*from);
  const auto to = openSqliteStore(dir / "fleet.db");
  // The fleet already has one of the robot's textures (the same pixels) from its own run.
  const std::int64_t own_run = to->beginRun("fleet's own");
  to->commit({{makeTexture(2, 40, 20)}, {}, {}});
  to->finishRun(own_run);

  std::size_t last_done = 0, last_total = 0;
  const CopyReport first = copyStore(*from, *to, [&](std::size_t done, std::size_t total) {
    EXPECT_GT(done, last_done);
    last_done = done;
    last_total = total;
  });
  EXPECT_EQ(last_total, from->textures().size());
  EXPECT_EQ(last_done, last_total);
  EXPECT_EQ(first.runs_copied, 1u);
  EXPECT_EQ(first.textures_already_there, 1u);
  EXPECT_EQ(first.textures_copied, from->textures().size() - 1);
  EXPECT_EQ(first.instances_copied, from->instances().size());
  EXPECT_EQ(to->stats().textures, from->stats().textures);
  EXPECT_EQ(instancesByContent(*to), instancesByContent(*from));
  const std::vector<RunRecord> runs = to->runs();
  ASSERT_EQ(runs.size(), 2u);
  EXPECT_NE(runs[1].source.find("recordings/office.oni [copied: run 1 started "),
            std::string::npos)
      << runs[1].source;
  EXPECT_TRUE(runs[1].finished);
  // A copied texture belongs to the copied run when it belonged to a run (commitRun's first
  // two do; the second of them was already in the fleet's database, unowned).
  std::size_t owned = 0;
  for (const TextureSummary& t : to->textures()) owned += t.run_id == runs[1].id ? 1 : 0;
  EXPECT_EQ(owned, 1u);

  const CopyReport again = copyStore(*from, *to);
  EXPECT_EQ(again.runs_copied, 0u);
  EXPECT_EQ(again.runs_already_there, 1u);
  EXPECT_EQ(again.textures_copied, 0u);
  EXPECT_EQ(to->runs().size(), 2u);
  EXPECT_EQ(to->stats().textures, from->stats().textures);
  EXPECT_EQ(to->stats().instances, from->stats().instances);
}

}  // namespace
}  // namespace tessera::db
