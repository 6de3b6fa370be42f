// Schema 2 of the SQLite texture store: instances in layers (0 the patch's texture, 1..
// overlays), how versions of a patch replace its layers, and version-1 files (read as they
// are when read-only, migrated when opened for writing).
#include <filesystem>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#include "store_test_support.h"
#include "tessera/db/texture_store.h"

namespace tessera::db::test {
namespace {

// Every field of an instance, so that whole lists compare (and print) at once.
using InstanceFields = std::tuple<std::int64_t, int, int, int, std::int64_t, double, double, double,
                                  double, std::optional<double>, bool>;

InstanceFields fieldsOf(const TextureInstance& i) {
  return {i.run_id,      i.patch_id,     i.version,      i.layer,   i.texture_id, i.transform.a,
          i.transform.b, i.transform.tx, i.transform.ty, i.psnr_db, i.reused};
}

std::vector<InstanceFields> fieldsOf(const std::vector<TextureInstance>& instances) {
  std::vector<InstanceFields> fields;
  for (const TextureInstance& i : instances) fields.push_back(fieldsOf(i));
  return fields;
}

// An instance whose transform and fidelity follow its layer, so that layers are told apart.
TextureInstance layerInstance(std::int64_t run, int patch, int version, int layer,
                              std::int64_t texture_id) {
  TextureInstance i;
  i.run_id = run;
  i.patch_id = patch;
  i.version = version;
  i.layer = layer;
  i.texture_id = texture_id;
  i.transform = core::Similarity2::fromAngleScale(0.1 * layer, 1.0 + layer, 3.0 * layer, -1.5);
  if (layer > 0) i.psnr_db = 30.0 + layer;
  i.reused = layer > 0;
  return i;
}

// One commit of `layers` layers of a patch, each layer a new texture (seeded by `seed` + layer).
// Returns the texture ids, by layer.
std::vector<std::int64_t> commitLayers(TextureStore& store, std::int64_t run, int patch,
                                       int version, int layers, std::uint32_t seed) {
  Commit commit;
  for (int layer = 0; layer < layers; ++layer) {
    commit.textures.push_back(makeTexture(seed + static_cast<std::uint32_t>(layer)));
    commit.instances.push_back(layerInstance(run, patch, version, layer, -(layer + 1)));
  }
  return store.commit(commit);
}

std::size_t usesOf(const TextureStore& store, std::int64_t texture_id) {
  for (const TextureSummary& s : store.textures()) {
    if (s.id == texture_id) return s.uses;
  }
  ADD_FAILURE() << "no texture " << texture_id;
  return 0;
}

TEST(SqliteStoreLayers, LayersOfOnePatchRoundTripInLayerOrder) {
  TempFolder dir;
  const auto path = dir / "textures.db";
  std::vector<InstanceFields> expected;
  {
    auto store = openSqliteStore(path);
    const std::int64_t run = store->beginRun("poster wall");
    Commit commit;
    commit.textures = {makeTexture(50), makeTexture(51), makeTexture(52)};
    // Out of order on purpose: reads order by run, patch, layer. Patch 4 shares the base.
    commit.instances = {layerInstance(run, 5, 1, 2, -3), layerInstance(run, 5, 1, 0, -1),
                        layerInstance(run, 4, 1, 0, -1), layerInstance(run, 5, 1, 1, -2)};
    const auto ids = store->commit(commit);
    ASSERT_EQ(ids.size(), 3u);
    expected = {fieldsOf(layerInstance(run, 4, 1, 0, ids[0])),
                fieldsOf(layerInstance(run, 5, 1, 0, ids[0])),
                fieldsOf(layerInstance(run, 5, 1, 1, ids[1])),
                fieldsOf(layerInstance(run, 5, 1, 2, ids[2]))};
    EXPECT_EQ(fieldsOf(store->instances()), expected);
    EXPECT_EQ(fieldsOf(store->instances(run)), expected);
    EXPECT_EQ(usesOf(*store, ids[0]), 2u);
    EXPECT_EQ(usesOf(*store, ids[1]), 1u);
    EXPECT_EQ(usesOf(*store, ids[2]), 1u);
    EXPECT_EQ(store->stats().instances, 4u);
  }
  auto read_only = openSqliteStore(path, {.create = false, .read_only = true});
  EXPECT_EQ(fieldsOf(read_only->instances()), expected);
  EXPECT_EQ(read_only->stats().schema_version, kSchemaVersion);
}

TEST(SqliteStoreLayers, NewerVersionReplacesEveryLayerOfItsPatch) {
  TempFolder dir;
  auto store = openSqliteStore(dir / "textures.db");
  const std::int64_t run = store->beginRun("test");
  const std::int64_t other_run = store->beginRun("test again");
  const auto old_ids = commitLayers(*store, run, 5, 1, 3, 60);
  commitLayers(*store, run, 6, 1, 2, 70);        // another patch of the run
  commitLayers(*store, other_run, 5, 1, 2, 80);  // the same patch id in another run
  ASSERT_EQ(store->instances(run).size(), 5u);

  const auto new_ids = commitLayers(*store, run, 5, 2, 1, 90);  // the overlays are gone
  const auto instances = store->instances(run);
  ASSERT_EQ(instances.size(), 3u);
  EXPECT_EQ(fieldsOf(instances[0]), fieldsOf(layerInstance(run, 5, 2, 0, new_ids[0])));
  EXPECT_EQ(instances[1].patch_id, 6);
  EXPECT_EQ(instances[2].patch_id, 6);
  EXPECT_EQ(instances[2].layer, 1);
  EXPECT_EQ(store->instances(other_run).size(), 2u);
  EXPECT_EQ(store->stats().instances, 5u);
  for (const std::int64_t id : old_ids) EXPECT_EQ(usesOf(*store, id), 0u) << id;

  // One commit may carry an older and a newer version: the newer wins whatever the order.
  Commit mixed;
  mixed.textures = {makeTexture(95), makeTexture(96), makeTexture(97)};
  mixed.instances = {layerInstance(run, 6, 3, 0, -1), layerInstance(run, 6, 2, 0, -2),
                     layerInstance(run, 6, 2, 1, -3)};
  const auto mixed_ids = store->commit(mixed);
  const auto after = store->instances(run);
  ASSERT_EQ(after.size(), 2u);
  EXPECT_EQ(fieldsOf(after[1]), fieldsOf(layerInstance(run, 6, 3, 0, mixed_ids[0])));
}

TEST(SqliteStoreLayers, OlderVersionArrivingLateChangesNothing) {
  TempFolder dir;
  const auto path = dir / "textures.db";
  auto store = openSqliteStore(path);
  const std::int64_t run = store->beginRun("test");
  commitLayers(*store, run, 5, 2, 2, 100);
  const auto before = fieldsOf(store->instances());
  ASSERT_EQ(before.size(), 2u);
  // Version 1 with more layers than version 2 has: not one of them is stored.
  const auto late_ids = commitLayers(*store, run, 5, 1, 4, 110);
  EXPECT_EQ(fieldsOf(store->instances()), before);
  EXPECT_EQ(rawQuery(path, "SELECT count(*) FROM instances WHERE version = 1"), "0");
  for (const std::int64_t id : late_ids) EXPECT_EQ(usesOf(*store, id), 0u) << id;
}

TEST(SqliteStoreLayers, SameVersionReplacesOnlyTheLayersItCarries) {
  TempFolder dir;
  auto store = openSqliteStore(dir / "textures.db");
  const std::int64_t run = store->beginRun("test");
  const auto ids = commitLayers(*store, run, 5, 1, 3, 120);
  Commit again;  // layer 1 of the same version again, with another texture
  again.textures = {makeTexture(130)};
  again.instances = {layerInstance(run, 5, 1, 1, -1)};
  const auto again_ids = store->commit(again);
  const std::vector<InstanceFields> expected = {fieldsOf(layerInstance(run, 5, 1, 0, ids[0])),
                                                fieldsOf(layerInstance(run, 5, 1, 1, again_ids[0])),
                                                fieldsOf(layerInstance(run, 5, 1, 2, ids[2]))};
  EXPECT_EQ(fieldsOf(store->instances()), expected);
}

// A patch merged into another after a loop closure leaves the database with every layer; the
// same patch id of another run, and the patch it merged into, keep theirs.
TEST(SqliteStoreLayers, ARetiredPatchLosesEveryLayerOfItsRunOnly) {
  TempFolder dir;
  auto store = openSqliteStore(dir / "textures.db");
  const std::int64_t run = store->beginRun("loop");
  const std::int64_t other_run = store->beginRun("loop again");
  const auto wall = commitLayers(*store, run, 3, 1, 1, 70);
  const auto doubled = commitLayers(*store, run, 8, 2, 2, 71);
  commitLayers(*store, other_run, 8, 1, 1, 73);
  Commit retire;
  retire.retired.push_back({run, 8});
  // The merged wall's new version in the same transaction, as the textures it reuses.
  retire.instances.push_back(layerInstance(run, 3, 2, 0, wall[0]));
  EXPECT_TRUE(store->commit(retire).empty());
  const std::vector<TextureInstance> left = store->instances(run);
  ASSERT_EQ(left.size(), 1u);
  EXPECT_EQ(fieldsOf(left.front()), fieldsOf(layerInstance(run, 3, 2, 0, wall[0])));
  ASSERT_EQ(store->instances(other_run).size(), 1u);
  EXPECT_EQ(store->instances(other_run).front().patch_id, 8);
  // The textures stay: the database is a library other runs may reuse.
  EXPECT_EQ(store->stats().textures, 4u);
  EXPECT_EQ(usesOf(*store, doubled[0]), 0u);
}

TEST(SqliteStoreLayers, NegativeLayerIsRefused) {
  TempFolder dir;
  const auto path = dir / "textures.db";
  auto store = openSqliteStore(path);
  const std::int64_t run = store->beginRun("test");
  Commit commit;
  commit.textures = {makeTexture(140)};
  commit.instances = {layerInstance(run, 5, 1, -1, -1)};
  const std::string message = errorOf([&] { store->commit(commit); });
  EXPECT_NE(message.find(path.string()), std::string::npos) << message;
  EXPECT_NE(message.find("patch 5 layer -1"), std::string::npos) << message;
  EXPECT_TRUE(store->textures().empty());
}

// A copy of schema version 1 as tessera wrote it, with two runs, two textures (their PNG a
// stand-in: these tests never decode it) and three instances. application_id 1413829459 is
// 0x54455353, "TESS".
constexpr const char* kVersion1Sql = R"sql(
CREATE TABLE meta (
  key TEXT PRIMARY KEY,
  value TEXT NOT NULL
);
CREATE TABLE runs (
  id INTEGER PRIMARY KEY,
  started_utc TEXT NOT NULL,
  source TEXT NOT NULL,
  finished INTEGER NOT NULL DEFAULT 0
);
CREATE TABLE textures (
  id INTEGER PRIMARY KEY,
  kind TEXT NOT NULL CHECK (kind IN ('single', 'pattern')),
  width INTEGER NOT NULL,
  height INTEGER NOT NULL,
  texel_m REAL NOT NULL,
  png BLOB NOT NULL,
  ccv BLOB,
  feature_kind TEXT NOT NULL,
  keypoints BLOB,
  descriptors BLOB,
  lattice_v1x REAL, lattice_v1y REAL, lattice_v2x REAL, lattice_v2y REAL,
  content_key TEXT NOT NULL UNIQUE,
  run_id INTEGER REFERENCES runs(id),
  source_patch INTEGER NOT NULL,
  name TEXT NOT NULL
);
CREATE TABLE instances (
  run_id INTEGER NOT NULL REFERENCES runs(id),
  patch_id INTEGER NOT NULL,
  version INTEGER NOT NULL,
  texture_id INTEGER NOT NULL REFERENCES textures(id),
  a REAL NOT NULL, b REAL NOT NULL, tx REAL NOT NULL, ty REAL NOT NULL,
  psnr_db REAL,
  reused INTEGER NOT NULL,
  UNIQUE (run_id, patch_id)
);
CREATE INDEX instances_by_texture ON instances (texture_id);
INSERT INTO meta (key, value) VALUES ('schema_version', '1'), ('application', 'tessera'),
  ('created_utc', '2026-01-01T00:00:00Z');
PRAGMA application_id = 1413829459;
PRAGMA user_version = 1;
INSERT INTO runs (id, started_utc, source, finished) VALUES
  (1, '2026-01-01T00:00:00Z', 'office.oni', 1), (2, '2026-01-02T00:00:00Z', 'office.oni', 0);
INSERT INTO textures (id, kind, width, height, texel_m, png, feature_kind, content_key, run_id,
                      source_patch, name) VALUES
  (1, 'single', 32, 24, 0.004, X'89504E470D0A1A0A', 'sift', '0123456789abcdef', 1, 7, ''),
  (2, 'pattern', 16, 16, 0.004, X'89504E470D0A1A0A', '', 'fedcba9876543210', 1, 8, '');
INSERT INTO instances (run_id, patch_id, version, texture_id, a, b, tx, ty, psnr_db, reused)
  VALUES (1, 7, 3, 1, 1.0, 0.0, 0.0, 0.0, NULL, 0),
         (1, 8, 1, 2, 0.5, 0.25, 2.0, -3.0, NULL, 0),
         (2, 7, 1, 1, 0.0, 1.0, 4.0, 5.0, 31.5, 1);
)sql";

// The instances kVersion1Sql holds, as schema 2 reads them: layer 0.
std::vector<InstanceFields> version1Instances() {
  return {{1, 7, 3, 0, 1, 1.0, 0.0, 0.0, 0.0, std::nullopt, false},
          {1, 8, 1, 0, 2, 0.5, 0.25, 2.0, -3.0, std::nullopt, false},
          {2, 7, 1, 0, 1, 0.0, 1.0, 4.0, 5.0, 31.5, true}};
}

// The instances table's columns (name, type, NOT NULL, default) and the columns of its UNIQUE
// constraint and of its other indexes, to compare a migrated file with a new one.
std::string instancesShape(const std::filesystem::path& path) {
  return rawQuery(path,
                  "SELECT group_concat(name || ' ' || type || ' ' || \"notnull\" || ' ' || "
                  "coalesce(dflt_value, '-'), ', ') FROM pragma_table_info('instances')") +
         " | " +
         rawQuery(path,
                  "SELECT group_concat(il.\"unique\" || ':' || ii.name, ', ') FROM "
                  "pragma_index_list('instances') il, pragma_index_info(il.name) ii") +
         " | " +
         rawQuery(path,
                  "SELECT group_concat(name, ', ') FROM sqlite_master WHERE type = 'index' "
                  "AND tbl_name = 'instances' AND sql IS NOT NULL");
}

TEST(SqliteStoreMigration, ReadOnlyOpenReadsAVersion1FileWithoutChangingIt) {
  TempFolder dir;
  const auto path = dir / "v1.db";
  rawExec(path, kVersion1Sql);
  const std::string bytes = fileContents(path);
  const auto mtime = std::filesystem::last_write_time(path);
  const auto listing = folderListing(dir.path());
  {
    auto store = openSqliteStore(path, {.create = false, .read_only = true});
    EXPECT_EQ(fieldsOf(store->instances()), version1Instances());
    ASSERT_EQ(store->instances(2).size(), 1u);
    EXPECT_EQ(store->instances(2)[0].psnr_db, 31.5);
    const StoreStats stats = store->stats();
    EXPECT_EQ(stats.schema_version, 1);
    EXPECT_EQ(stats.instances, 3u);
    EXPECT_EQ(stats.textures, 2u);
    EXPECT_EQ(stats.patterns, 1u);
    EXPECT_EQ(usesOf(*store, 1), 2u);
    EXPECT_EQ(usesOf(*store, 2), 1u);
    const std::string message = errorOf([&] { store->beginRun("x"); });
    EXPECT_NE(message.find("read-only"), std::string::npos) << message;
  }
  EXPECT_EQ(fileContents(path), bytes);
  EXPECT_EQ(std::filesystem::last_write_time(path), mtime);
  EXPECT_EQ(folderListing(dir.path()), listing);  // no -wal, -shm or -journal left beside it
}

TEST(SqliteStoreMigration, WritableOpenMigratesAVersion1FileKeepingItsInstances) {
  TempFolder dir;
  const auto path = dir / "v1.db";
  rawExec(path, kVersion1Sql);
  {
    auto store = openSqliteStore(path, {.create = false, .read_only = false});
    EXPECT_EQ(store->stats().schema_version, kSchemaVersion);
    EXPECT_EQ(fieldsOf(store->instances()), version1Instances());
    EXPECT_EQ(usesOf(*store, 1), 2u);
    // The migrated table takes layers: two overlays on patch 7 of run 1, same version.
    Commit overlays;
    overlays.textures = {makeTexture(150), makeTexture(151)};
    overlays.instances = {layerInstance(1, 7, 3, 1, -1), layerInstance(1, 7, 3, 2, -2)};
    store->commit(overlays);
    EXPECT_EQ(store->instances(1).size(), 4u);
    // A newer version of patch 8 replaces its migrated instance.
    commitLayers(*store, 1, 8, 2, 2, 160);
    const auto run1 = store->instances(1);
    ASSERT_EQ(run1.size(), 5u);
    EXPECT_EQ(run1[3].patch_id, 8);
    EXPECT_EQ(run1[3].version, 2);
  }
  EXPECT_EQ(rawQuery(path, "SELECT value FROM meta WHERE key = 'schema_version'"),
            std::to_string(kSchemaVersion));
  EXPECT_EQ(rawQuery(path, "PRAGMA user_version"), std::to_string(kSchemaVersion));
  EXPECT_EQ(rawQuery(path, "PRAGMA integrity_check"), "ok");
  EXPECT_EQ(rawQuery(path, "SELECT count(*) FROM sqlite_master WHERE name = 'instances_v2'"), "0");
  const auto fresh = dir / "fresh.db";
  openSqliteStore(fresh).reset();
  EXPECT_EQ(instancesShape(path), instancesShape(fresh));
  EXPECT_NE(instancesShape(fresh).find("1:run_id, 1:patch_id, 1:layer"), std::string::npos)
      << instancesShape(fresh);
  // Opened again: nothing left to migrate, and the rows are still there.
  auto reopened = openSqliteStore(path);
  EXPECT_EQ(reopened->stats().instances, 6u);
}

TEST(SqliteStoreMigration, FailedMigrationLeavesTheVersion1FileAsItWas) {
  TempFolder dir;
  const auto path = dir / "v1.db";
  // A table in the way of the migration's new one: creating it fails half-way through.
  rawExec(path, std::string(kVersion1Sql) + "CREATE TABLE instances_v2 (x);");
  const std::string bytes = fileContents(path);
  const auto listing = folderListing(dir.path());
  const std::string message =
      errorOf([&] { openSqliteStore(path, {.create = false, .read_only = false}); });
  EXPECT_NE(message.find(path.string()), std::string::npos) << message;
  EXPECT_NE(message.find("migrating it to schema 2"), std::string::npos) << message;
  EXPECT_EQ(fileContents(path), bytes);
  EXPECT_EQ(folderListing(dir.path()), listing);
  auto read_only = openSqliteStore(path, {.create = false, .read_only = true});
  EXPECT_EQ(fieldsOf(read_only->instances()), version1Instances());
}

TEST(SqliteStoreLayers, OnlyTheRunsUnusedTexturesAreRemoved) {
  TempFolder dir;
  const auto path = dir / "textures.db";
  {
    auto store = openSqliteStore(path);
    expectOnlyTheRunsUnusedTexturesAreRemoved(*store);
  }
  // Read-only, it removes nothing and says why.
  auto reader = openSqliteStore(path, {.create = false, .read_only = true});
  const std::int64_t any = reader->textures().at(0).id;
  EXPECT_NE(errorOf([&] { reader->removeUnused(1, {any}); }).find("read-only"), std::string::npos);
  EXPECT_TRUE(reader->texture(any).has_value());
}

}  // namespace
}  // namespace tessera::db::test
