// The PostgreSQL store against a real, throwaway server (support/postgres_cluster.h): the same
// results as the SQLite store, concurrent writers storing each texture once, a newer schema
// refused, and credentials kept out of every message. Skips without the server binaries.
#include <fstream>
#include <set>
#include <thread>
#include <tuple>

#include <opencv2/core.hpp>

#include "db/store_test_support.h"
#include "support/postgres_test.h"
#include "tessera/db/store_copy.h"
#include "tessera/db/store_prune.h"
#include "tessera/db/texture_store.h"

namespace tessera::db {

namespace internal {
std::string redactedUrl(const std::string& url);
}

namespace {

using test::errorOf;
using test::makeTexture;
using test::TempFolder;
using test::commitRun;
using test::keysOf;

using PostgresStoreTest = tessera::test::PostgresTest;

TEST_F(PostgresStoreTest, TheSameCommitsReadTheSameFromBothStores) {
  test::TempFolder folder;
  const auto sqlite = openSqliteStore(folder / "textures.db");
  const auto postgres = openTextureStore(freshDatabase());
  commitRun(*sqlite);
  commitRun(*postgres);

  EXPECT_EQ(keysOf(sqlite->instances()), keysOf(postgres->instances()));
  const auto a = sqlite->textures(), b = postgres->textures();
  ASSERT_EQ(a.size(), 3u);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].id, b[i].id);
    EXPECT_EQ(a[i].kind, b[i].kind);
    EXPECT_EQ(a[i].width, b[i].width);
    EXPECT_EQ(a[i].uses, b[i].uses);
    EXPECT_EQ(a[i].png_bytes, b[i].png_bytes);  // the same PNG bytes
    const auto ra = sqlite->texture(a[i].id), rb = postgres->texture(b[i].id);
    ASSERT_TRUE(ra && rb);
    EXPECT_EQ(cv::norm(ra->rgb, rb->rgb, cv::NORM_INF), 0.0);
    EXPECT_EQ(cv::norm(ra->mask, rb->mask, cv::NORM_INF), 0.0);
    EXPECT_EQ(ra->ccv, rb->ccv);
    EXPECT_EQ(ra->keypoints.size(), rb->keypoints.size());
    EXPECT_EQ(cv::norm(ra->descriptors, rb->descriptors, cv::NORM_INF), 0.0);
    EXPECT_EQ(ra->content_key, rb->content_key);
    EXPECT_EQ(ra->lattice.has_value(), rb->lattice.has_value());
    EXPECT_EQ(postgres->findByContentKey(ra->content_key), b[i].id);
  }
  const auto psnr = [](const std::vector<TextureInstance>& all) {
    for (const TextureInstance& i : all) {
      if (i.patch_id == 1 && i.layer == 0) return i.psnr_db;
    }
    return std::optional<double>();
  };
  EXPECT_EQ(psnr(postgres->instances()), std::optional<double>(31.5));
  EXPECT_EQ(postgres->ccvVectors(1).size(), 2u);
  const StoreStats sa = sqlite->stats(), sb = postgres->stats();
  EXPECT_EQ(sa.schema_version, sb.schema_version);
  EXPECT_EQ(sa.textures, sb.textures);
  EXPECT_EQ(sa.patterns, sb.patterns);
  EXPECT_EQ(sa.instances, sb.instances);
  EXPECT_EQ(sa.texture_pixels, sb.texture_pixels);
  ASSERT_EQ(postgres->runs().size(), 1u);
  EXPECT_TRUE(postgres->runs()[0].finished);
}

TEST_F(PostgresStoreTest, OnlyTheRunsUnusedTexturesAreRemoved) {
  const auto store = openTextureStore(freshDatabase());
  test::expectOnlyTheRunsUnusedTexturesAreRemoved(*store);
}

// Four writers at once, each with its own connections (as four robots would), commit textures
// that overlap: each distinct image is stored once, and every instance is kept.
TEST_F(PostgresStoreTest, ConcurrentWritersStoreEachTextureOnce) {
  const std::string url = freshDatabase();
  openTextureStore(url);  // creates the schema
  constexpr int kWriters = 4, kCommits = 12;
  std::vector<std::thread> writers;
  std::atomic<int> failures{0};
  for (int w = 0; w < kWriters; ++w) {
    writers.emplace_back([&, w] {
      try {
        const auto store = openTextureStore(url);
        const std::int64_t run = store->beginRun("writer " + std::to_string(w));
        for (int c = 0; c < kCommits; ++c) {
          Commit commit;
          // Shared images 0..5 in a writer-dependent order, and one of the writer's own.
          commit.textures = {makeTexture(static_cast<std::uint32_t>((c + w) % 6)),
                             makeTexture(static_cast<std::uint32_t>(1000 + 100 * w + c))};
          for (int k = 0; k < 2; ++k) {
            TextureInstance i;
            i.run_id = run;
            i.patch_id = 2 * c + k;
            i.version = 1;
            i.texture_id = -(k + 1);
            commit.instances.push_back(i);
          }
          store->commit(commit);
        }
        store->finishRun(run);
      } catch (const std::exception& e) {
        ADD_FAILURE() << "writer " << w << ": " << e.what();
        ++failures;
      }
    });
  }
  for (std::thread& t : writers) t.join();
  ASSERT_EQ(failures.load(), 0);
  const auto store = openTextureStore(url, {false, true});
  const StoreStats stats = store->stats();
  EXPECT_EQ(stats.textures, 6u + kWriters * kCommits);  // the shared six once each
  EXPECT_EQ(stats.instances, static_cast<std::size_t>(kWriters * kCommits * 2));
  EXPECT_EQ(stats.runs, static_cast<std::size_t>(kWriters));
  std::set<std::string> keys;
  for (const TextureSummary& t : store->textures()) {
    keys.insert(store->texture(t.id)->content_key);
  }
  EXPECT_EQ(keys.size(), stats.textures);
}

TEST_F(PostgresStoreTest, ANewerSchemaIsRefusedBeforeAnythingIsWritten) {
  const std::string url = freshDatabase();
  { openTextureStore(url)->beginRun("first"); }
  ASSERT_TRUE(cluster_->psql("UPDATE meta SET value = '99' WHERE key = 'schema_version'",
                             url.substr(url.rfind('/') + 1)));
  const std::string message = errorOf([&] { openTextureStore(url); });
  EXPECT_NE(message.find("newer tessera (schema 99; this build reads up to 2)"),
            std::string::npos)
      << message;
  EXPECT_NE(message.find("127.0.0.1"), std::string::npos) << message;
}

TEST_F(PostgresStoreTest, AForeignDatabaseAndAMissingOneAreClearErrors) {
  const std::string url = freshDatabase();
  const std::string missing = errorOf([&] { openTextureStore(url, {false, true}); });
  EXPECT_NE(missing.find("no tessera texture database there"), std::string::npos) << missing;
  ASSERT_TRUE(cluster_->psql("CREATE TABLE textures (id integer)", url.substr(url.rfind('/') + 1)));
  const std::string foreign = errorOf([&] { openTextureStore(url); });
  EXPECT_NE(foreign.find("not a tessera texture database"), std::string::npos) << foreign;
}

// A password in the URL is used by libpq but never shown: not in location(), not in the
// message of a failed connection.
TEST_F(PostgresStoreTest, CredentialsNeverAppearInLocationsOrMessages) {
  const std::string secret = "hunter2-Secret";
  EXPECT_EQ(internal::redactedUrl("postgresql://robot:" + secret + "@db.local:5432/fleet"),
            "postgresql://robot@db.local:5432/fleet");
  EXPECT_EQ(internal::redactedUrl("postgresql://db.local/fleet?user=robot&password=" + secret +
                                  "&sslmode=require"),
            "postgresql://db.local/fleet?user=robot&sslmode=require");
  // The right password in the URL: the store works, and shows none.
  const std::string url = freshDatabase();
  const std::string password = tessera::test::PostgresCluster::password();
  const std::string with_password = "postgresql://tessera:" + password + url.substr(20);
  const auto store = openTextureStore(with_password);
  EXPECT_EQ(store->location().find(password), std::string::npos) << store->location();
  // Nothing listens on port 1: the connection fails, and the message names the server only.
  const std::string refused =
      errorOf([&] { openTextureStore("postgresql://robot:" + secret + "@127.0.0.1:1/fleet"); });
  EXPECT_EQ(refused.find(secret), std::string::npos) << refused;
  EXPECT_NE(refused.find("postgresql://robot@127.0.0.1:1/fleet: cannot connect"),
            std::string::npos)
      << refused;
}

// The server goes away and comes back: the commits made while it is away wait in the journal
// and reach the server, in order, when it is back; the run's end waits for them.
// A robot's SQLite database into the fleet's server, and from there into a fresh file: the
// same textures and instances all the way.
TEST_F(PostgresStoreTest, ADatabaseCopiedToTheServerAndBackHoldsTheSame) {
  TempFolder dir;
  const auto robot = openSqliteStore(dir / "robot.db");
  commitRun(*robot);
  const auto fleet = openTextureStore(freshDatabase());
  const CopyReport up = copyStore(*robot, *fleet);
  EXPECT_EQ(up.textures_copied, robot->stats().textures);
  const auto back = openSqliteStore(dir / "back.db");
  copyStore(*fleet, *back);
  for (const TextureStore* store : {fleet.get(), back.get()}) {
    EXPECT_EQ(store->stats().textures, robot->stats().textures);
    EXPECT_EQ(store->stats().instances, robot->stats().instances);
    std::set<std::string> keys, robot_keys;
    for (const TextureSummary& t : store->textures()) keys.insert(store->texture(t.id)->content_key);
    for (const TextureSummary& t : robot->textures()) {
      robot_keys.insert(robot->texture(t.id)->content_key);
    }
    EXPECT_EQ(keys, robot_keys);
  }
  EXPECT_EQ(copyStore(*robot, *fleet).textures_copied, 0u);
}

// A commit naming a texture or a run the database does not have is refused whole, with the
// SQLite store's messages.
TEST_F(PostgresStoreTest, ACommitNamingAMissingTextureOrRunIsRefusedWhole) {
  const auto store = openTextureStore(freshDatabase());
  const std::int64_t run = store->beginRun("office");
  Commit commit;
  commit.textures = {makeTexture(5)};
  TextureInstance instance;
  instance.run_id = run;
  instance.patch_id = 3;
  instance.version = 1;
  instance.texture_id = 77;
  commit.instances = {instance};
  const std::string texture = errorOf([&] { store->commit(commit); });
  EXPECT_NE(texture.find("the instance of patch 3 refers to texture 77, which is not stored"),
            std::string::npos)
      << texture;
  commit.instances[0].texture_id = -1;
  commit.instances[0].run_id = run + 5;
  const std::string missing_run = errorOf([&] { store->commit(commit); });
  EXPECT_NE(missing_run.find("belongs to run " + std::to_string(run + 5) + ", which is not stored"),
            std::string::npos)
      << missing_run;
  EXPECT_EQ(store->stats().textures, 0u);  // rolled back with the instance
}

// docs/FLEET.md's SQL for a robot's role, as written there (its password and database
// replaced).
std::string robotRoleSql(const std::string& role, const std::string& password,
                         const std::string& database) {
  std::ifstream in(std::string(TESSERA_SOURCE_DIR) + "/docs/FLEET.md");
  std::string line, sql;
  bool inside = false;
  while (std::getline(in, line)) {
    if (line == "```sql") {
      inside = true;
    } else if (inside && line == "```") {
      break;
    } else if (inside) {
      sql += line + '\n';
    }
  }
  const auto replaceAll = [&sql](const std::string& from, const std::string& to) {
    for (std::size_t at = sql.find(from); at != std::string::npos; at = sql.find(from, at)) {
      sql.replace(at, from.size(), to);
      at += to.size();
    }
  };
  replaceAll("'...'", "'" + password + "'");
  replaceAll("building7", database);
  replaceAll("ROLE robot ", "ROLE " + role + " ");
  replaceAll(" TO robot;", " TO " + role + ";");
  return sql;
}

TEST_F(PostgresStoreTest, ARobotsRoleCommitsAndReadsButCannotDropOrMigrate) {
  const std::string url = freshDatabase();
  const std::string database = url.substr(url.rfind('/') + 1);
  openTextureStore(url);  // the owner creates the tables
  const std::string sql = robotRoleSql("robot_role_test", "robot-pw", database);
  ASSERT_NE(sql.find("GRANT SELECT, INSERT ON textures TO robot_role_test;"), std::string::npos)
      << sql;
  ASSERT_TRUE(cluster_->psql(sql, database));
  std::string as_robot = url;
  as_robot.replace(as_robot.find("tessera@"), 8, "robot_role_test:robot-pw@");
  {
    const auto store = openTextureStore(as_robot);
    commitRun(*store);
    EXPECT_EQ(store->stats().textures, 3u);
    // The retired patch's texture is unused; this role may not delete it (said once).
    std::vector<std::int64_t> all;
    for (const TextureSummary& t : store->textures()) all.push_back(t.id);
    EXPECT_TRUE(store->removeUnused(store->runs().at(0).id, all).empty());
    EXPECT_TRUE(store->removeUnused(store->runs().at(0).id, all).empty());
    EXPECT_EQ(store->stats().textures, 3u);
  }
  {  // the owner's prune does
    const auto owner = openTextureStore(url);
    EXPECT_EQ(pruneUnused(*owner).removed, 1u);
    EXPECT_EQ(owner->stats().textures, 2u);
  }
  EXPECT_FALSE(cluster_->psql("DROP TABLE textures", database, "robot_role_test"));
  EXPECT_FALSE(cluster_->psql("DELETE FROM textures", database, "robot_role_test"));
  // A migration (here: a database that says it is of schema 1) needs the owner.
  ASSERT_TRUE(cluster_->psql("UPDATE meta SET value = '1' WHERE key = 'schema_version'", database));
  const std::string message = errorOf([&] { openTextureStore(as_robot); });
  EXPECT_NE(message.find("not allowed to create or migrate the schema"), std::string::npos)
      << message;
}

TEST_F(PostgresStoreTest, AServerRestartMidRunLosesNoCommit) {
  const std::string url = freshDatabase();
  TempFolder dir;
  OpenOptions options;
  options.journal = dir / "journal.sqlite";
  const auto store = openTextureStore(url, options);
  const std::int64_t run = store->beginRun("restart");
  const auto commitOne = [&](std::uint32_t seed, int patch) {
    Commit commit;
    commit.textures = {makeTexture(seed)};
    TextureInstance i;
    i.run_id = run;
    i.patch_id = patch;
    i.version = 1;
    i.texture_id = -1;
    commit.instances = {i};
    return store->commit(commit).at(0);
  };
  commitOne(1, 1);
  ASSERT_TRUE(cluster_->stopServer());
  const std::int64_t queued = commitOne(2, 2);  // waits in the journal
  const std::int64_t also_queued = commitOne(3, 3);
  EXPECT_EQ(store->serverLink()->pending_commits, 2u);
  ASSERT_TRUE(cluster_->startServer());
  store->finishRun(run);  // waits for the journal to be sent first
  const ServerLink link = *store->serverLink();
  EXPECT_EQ(link.pending_commits, 0u);
  EXPECT_EQ(link.replayed_commits, 2u);
  EXPECT_EQ(link.outages, 1u);
  EXPECT_EQ(store->stats().textures, 3u);
  std::set<std::int64_t> shown;
  for (const TextureInstance& i : store->instances()) shown.insert(i.texture_id);
  EXPECT_EQ(shown.count(store->resolvedId(queued)), 1u);
  EXPECT_EQ(shown.count(store->resolvedId(also_queued)), 1u);
  EXPECT_TRUE(store->runs().at(0).finished);
}

TEST_F(PostgresStoreTest, AWrongPasswordIsOneClearErrorWithoutThePassword) {
  ASSERT_TRUE(cluster_->psql("CREATE ROLE robot LOGIN PASSWORD 'right-one'"));
  const std::string url = freshDatabase();
  std::string with_password = url;
  with_password.replace(with_password.find("tessera@"), 8, "robot:wrong-one@");
  const std::string message = errorOf([&] { openTextureStore(with_password); });
  EXPECT_NE(message.find("cannot connect"), std::string::npos) << message;
  EXPECT_EQ(message.find("wrong-one"), std::string::npos) << message;
}

}  // namespace
}  // namespace tessera::db
