// The SQLite texture store: round trips, deduplication, instance versions, and the files it
// refuses. Crash consistency and concurrency: sqlite_store_concurrency_test.cpp.
#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "store_test_support.h"
#include "tessera/db/texture_store.h"

namespace tessera::db::test {
namespace {

// Equal pixels and type; two empty matrices are equal whatever type they were released with.
bool sameMat(const cv::Mat& a, const cv::Mat& b) {
  if (a.empty() || b.empty()) return a.empty() && b.empty();
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0.0;
}

void expectSameTexture(const TextureRecord& stored, const TextureRecord& sent) {
  EXPECT_EQ(stored.kind, sent.kind);
  EXPECT_TRUE(sameMat(stored.rgb, sent.rgb));
  if (sent.mask.empty()) {
    EXPECT_EQ(cv::countNonZero(stored.mask == 255), sent.rgb.rows * sent.rgb.cols);
  } else {
    EXPECT_TRUE(sameMat(stored.mask, sent.mask));
  }
  EXPECT_EQ(stored.texel_m, sent.texel_m);
  EXPECT_EQ(stored.ccv, sent.ccv);
  EXPECT_EQ(stored.feature_kind, sent.feature_kind);
  ASSERT_EQ(stored.keypoints.size(), sent.keypoints.size());
  for (std::size_t i = 0; i < sent.keypoints.size(); ++i) {
    const cv::KeyPoint &a = stored.keypoints[i], &b = sent.keypoints[i];
    EXPECT_EQ(a.pt, b.pt);
    EXPECT_EQ(a.size, b.size);
    EXPECT_EQ(a.angle, b.angle);
    EXPECT_EQ(a.response, b.response);
    EXPECT_EQ(a.octave, b.octave);
    EXPECT_EQ(a.class_id, b.class_id);
  }
  EXPECT_TRUE(sameMat(stored.descriptors, sent.descriptors));
  ASSERT_EQ(stored.lattice.has_value(), sent.lattice.has_value());
  if (sent.lattice) {
    EXPECT_EQ(stored.lattice->v1, sent.lattice->v1);
    EXPECT_EQ(stored.lattice->v2, sent.lattice->v2);
  }
  EXPECT_EQ(stored.content_key, contentKey(sent.rgb, sent.mask));
  EXPECT_EQ(stored.run_id, sent.run_id);
  EXPECT_EQ(stored.source_patch, sent.source_patch);
  EXPECT_EQ(stored.name, sent.name);
}

// Three textures covering every field: a pattern with SIFT features and a lattice, an
// imported image with ORB (uint8) descriptors, and a featureless one without a mask.
Commit fullCommit(std::int64_t run) {
  Commit commit;
  TextureRecord pattern = makeTexture(1);
  pattern.kind = TextureKind::kPattern;
  pattern.lattice = Lattice{{8.0, 0.0}, {0.5, 7.25}};
  pattern.run_id = run;
  pattern.source_patch = 7;
  TextureRecord imported = makeTexture(2, 40, 20);
  imported.texel_m = 0.0;
  imported.feature_kind = "orb";
  imported.descriptors.create(4, 32, CV_8U);
  cv::randu(imported.descriptors, 0, 256);
  imported.name = "brick.png";
  TextureRecord plain = makeTexture(3, 16, 16);
  plain.mask.release();
  plain.ccv.clear();
  plain.feature_kind.clear();
  plain.keypoints.clear();
  plain.descriptors.release();
  plain.run_id = run;
  commit.textures = {pattern, imported, plain};
  TextureInstance first;
  first.run_id = run;
  first.patch_id = 7;
  first.version = 2;
  first.texture_id = -1;
  first.transform = core::Similarity2::fromAngleScale(0.3, 1.5, 2.0, -3.0);
  TextureInstance second = first;
  second.patch_id = 8;
  second.texture_id = -2;
  second.psnr_db = 31.5;
  second.reused = true;
  commit.instances = {first, second};
  return commit;
}

void expectFullContents(const TextureStore& store, const Commit& sent,
                        const std::vector<std::int64_t>& ids) {
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const auto stored = store.texture(ids[i]);
    ASSERT_TRUE(stored.has_value());
    EXPECT_EQ(stored->id, ids[i]);
    expectSameTexture(*stored, sent.textures[i]);
    EXPECT_EQ(store.findByContentKey(stored->content_key), ids[i]);
  }
  EXPECT_FALSE(store.texture(ids.back() + 100).has_value());

  const auto instances = store.instances();
  ASSERT_EQ(instances.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    const TextureInstance &got = instances[i], &want = sent.instances[i];
    EXPECT_EQ(got.run_id, want.run_id);
    EXPECT_EQ(got.patch_id, want.patch_id);
    EXPECT_EQ(got.version, want.version);
    EXPECT_EQ(got.layer, 0);
    EXPECT_EQ(got.texture_id, ids[i]);
    EXPECT_EQ(got.transform.a, want.transform.a);
    EXPECT_EQ(got.transform.b, want.transform.b);
    EXPECT_EQ(got.transform.tx, want.transform.tx);
    EXPECT_EQ(got.transform.ty, want.transform.ty);
    EXPECT_EQ(got.psnr_db, want.psnr_db);
    EXPECT_EQ(got.reused, want.reused);
  }
  EXPECT_EQ(store.instances(sent.instances[0].run_id).size(), 2u);
  EXPECT_TRUE(store.instances(sent.instances[0].run_id + 1).empty());

  const auto summaries = store.textures();
  ASSERT_EQ(summaries.size(), 3u);
  EXPECT_EQ(summaries[0].kind, TextureKind::kPattern);
  EXPECT_EQ(summaries[1].name, "brick.png");
  EXPECT_EQ(summaries[1].width, 40);
  EXPECT_EQ(summaries[1].height, 20);
  EXPECT_EQ(summaries[2].source_patch, -1);
  EXPECT_EQ(summaries[0].uses, 1u);
  EXPECT_EQ(summaries[1].uses, 1u);
  EXPECT_EQ(summaries[2].uses, 0u);
  for (const auto& s : summaries) EXPECT_GT(s.png_bytes, 0u);

  const auto ccvs = store.ccvVectors();
  ASSERT_EQ(ccvs.size(), 3u);
  EXPECT_EQ(ccvs[0].ccv, sent.textures[0].ccv);
  EXPECT_EQ(store.ccvVectors(ids[0]).size(), 2u);

  const StoreStats stats = store.stats();
  EXPECT_EQ(stats.schema_version, kSchemaVersion);
  EXPECT_EQ(stats.textures, 3u);
  EXPECT_EQ(stats.patterns, 1u);
  EXPECT_EQ(stats.instances, 2u);
  EXPECT_EQ(stats.runs, 1u);
  EXPECT_EQ(stats.texture_pixels, 32u * 24u + 40u * 20u + 16u * 16u);
  EXPECT_GT(stats.file_bytes, 0u);
}

TEST(SqliteStore, RoundTripsEveryFieldAndPersistsAfterReopening) {
  TempFolder dir;
  const auto path = dir / "textures.db";
  Commit sent;
  std::vector<std::int64_t> ids;
  {
    auto store = openSqliteStore(path);
    EXPECT_EQ(store->location(), path.string());
    const std::int64_t run = store->beginRun("office.oni");
    sent = fullCommit(run);
    ids = store->commit(sent);
    ASSERT_EQ(ids.size(), 3u);
    EXPECT_LT(ids[0], ids[1]);
    EXPECT_LT(ids[1], ids[2]);
    store->finishRun(run);
    expectFullContents(*store, sent, ids);
    const auto runs = store->runs();
    ASSERT_EQ(runs.size(), 1u);
    EXPECT_EQ(runs[0].id, run);
    EXPECT_EQ(runs[0].source, "office.oni");
    EXPECT_TRUE(runs[0].finished);
    EXPECT_EQ(runs[0].started_utc.size(), 20u) << runs[0].started_utc;  // 2024-05-01T12:00:00Z
    EXPECT_EQ(runs[0].started_utc.back(), 'Z');
    EXPECT_EQ(rawQuery(path, "PRAGMA journal_mode"), "wal");  // while a writer has it open
  }
  auto reopened = openSqliteStore(path);
  expectFullContents(*reopened, sent, ids);
  EXPECT_TRUE(reopened->runs()[0].finished);
  reopened.reset();
  auto read_only = openSqliteStore(path, {.create = false, .read_only = true});
  expectFullContents(*read_only, sent, ids);
  EXPECT_EQ(rawQuery(path, "PRAGMA user_version"), std::to_string(kSchemaVersion));
}

TEST(SqliteStore, SamePixelsAreStoredOnceAndKeepTheirId) {
  TempFolder dir;
  auto store = openSqliteStore(dir / "textures.db");
  const std::int64_t run = store->beginRun("test");
  Commit first;
  first.textures = {makeTexture(5)};
  const auto first_ids = store->commit(first);
  Commit second;  // the same pixels under another name, twice in one commit, and a new one
  second.textures = {makeTexture(5), makeTexture(5), makeTexture(6)};
  second.textures[0].name = "again.png";
  second.instances.push_back({run, 1, 1, 0, -2, {}, 40.0, true});
  const auto second_ids = store->commit(second);
  ASSERT_EQ(second_ids.size(), 3u);
  EXPECT_EQ(second_ids[0], first_ids[0]);
  EXPECT_EQ(second_ids[1], first_ids[0]);
  EXPECT_NE(second_ids[2], first_ids[0]);
  EXPECT_EQ(store->textures().size(), 2u);
  EXPECT_EQ(store->instances()[0].texture_id, first_ids[0]);
  EXPECT_EQ(store->texture(first_ids[0])->name, "");  // the first store wins
}

TEST(SqliteStore, NewerPatchVersionReplacesItsInstance) {
  TempFolder dir;
  auto store = openSqliteStore(dir / "textures.db");
  const std::int64_t run = store->beginRun("test");
  const std::int64_t other_run = store->beginRun("test again");
  const auto commitVersion = [&](std::int64_t run_id, int version, std::uint32_t seed) {
    Commit commit;
    commit.textures = {makeTexture(seed)};
    commit.instances.push_back({run_id, 3, version, 0, -1, {}, std::nullopt, false});
    return store->commit(commit)[0];
  };
  commitVersion(run, 1, 10);
  const std::int64_t newest = commitVersion(run, 2, 11);
  commitVersion(run, 1, 12);  // a late, older version does not win
  const auto instances = store->instances(run);
  ASSERT_EQ(instances.size(), 1u);
  EXPECT_EQ(instances[0].version, 2);
  EXPECT_EQ(instances[0].texture_id, newest);
  commitVersion(other_run, 1, 13);  // the same patch id in another run is another instance
  EXPECT_EQ(store->instances().size(), 2u);
  EXPECT_EQ(store->stats().instances, 2u);
}

TEST(SqliteStore, FailedCommitStoresNothingOfIt) {
  TempFolder dir;
  const auto path = dir / "textures.db";
  auto store = openSqliteStore(path);
  const std::int64_t run = store->beginRun("test");
  Commit good;
  good.textures = {makeTexture(20)};
  good.instances.push_back({run, 1, 1, 0, -1, {}, std::nullopt, false});
  store->commit(good);

  Commit missing_texture;  // a new texture, then an instance of a texture that does not exist
  missing_texture.textures = {makeTexture(21)};
  missing_texture.instances.push_back({run, 2, 1, 0, -1, {}, std::nullopt, false});
  missing_texture.instances.push_back({run, 3, 1, 0, 99999, {}, std::nullopt, false});
  std::string message = errorOf([&] { store->commit(missing_texture); });
  EXPECT_NE(message.find(path.string()), std::string::npos) << message;
  EXPECT_NE(message.find("99999"), std::string::npos) << message;

  Commit bad_run;  // refused by the foreign key inside SQLite, after the first insert
  bad_run.textures = {makeTexture(22), makeTexture(23)};
  bad_run.textures[1].run_id = 12345;
  message = errorOf([&] { store->commit(bad_run); });
  EXPECT_NE(message.find("FOREIGN KEY"), std::string::npos) << message;

  Commit bad_index;
  bad_index.textures = {makeTexture(24)};
  bad_index.instances.push_back({run, 4, 1, 0, -2, {}, std::nullopt, false});
  message = errorOf([&] { store->commit(bad_index); });
  EXPECT_NE(message.find("new texture 1"), std::string::npos) << message;

  EXPECT_EQ(store->textures().size(), 1u);
  EXPECT_EQ(store->instances().size(), 1u);
  for (std::uint32_t seed : {21u, 22u, 24u}) {
    const TextureRecord t = makeTexture(seed);
    EXPECT_FALSE(store->findByContentKey(contentKey(t.rgb, t.mask)).has_value()) << seed;
  }
  store->commit(good);  // the writer is usable after a failure
  EXPECT_EQ(store->textures().size(), 1u);
}

TEST(SqliteStore, RefusesANewerSchemaWithoutTouchingTheFile) {
  TempFolder dir;
  const auto path = dir / "textures.db";
  openSqliteStore(path)->commit({{makeTexture(30)}, {}, {}});
  const std::string newer = std::to_string(kSchemaVersion + 1);
  rawExec(path, "UPDATE meta SET value = '" + newer +
                    "' WHERE key = 'schema_version'; PRAGMA user_version = " + newer + ";");
  const std::string before = fileContents(path);
  const auto listing = folderListing(dir.path());
  for (bool read_only : {false, true}) {
    const std::string message =
        errorOf([&] { openSqliteStore(path, {.create = true, .read_only = read_only}); });
    EXPECT_NE(message.find(path.string()), std::string::npos) << message;
    EXPECT_NE(message.find("newer tessera (schema " + newer + "; this build reads up to " +
                           std::to_string(kSchemaVersion) + ")"),
              std::string::npos)
        << message;
  }
  EXPECT_EQ(fileContents(path), before);
  EXPECT_EQ(folderListing(dir.path()), listing);  // not even a -wal or -shm beside it
}

TEST(SqliteStore, RefusesANewerSchemaInTheMetaTable) {
  TempFolder dir;
  const auto path = dir / "textures.db";
  openSqliteStore(path)->commit({{makeTexture(31)}, {}, {}});
  const std::string newer = std::to_string(kSchemaVersion + 1);
  rawExec(path, "UPDATE meta SET value = '" + newer + "' WHERE key = 'schema_version'");
  const std::string before = fileContents(path);
  const std::string message = errorOf([&] { openSqliteStore(path); });
  EXPECT_NE(message.find(path.string()), std::string::npos) << message;
  EXPECT_NE(message.find("newer tessera (schema " + newer), std::string::npos) << message;
  EXPECT_EQ(fileContents(path), before);
}

TEST(SqliteStore, RefusesFilesThatAreNotTesseraDatabases) {
  TempFolder dir;
  const auto text = dir / "notes.txt";
  std::ofstream(text) << "not a database, just some notes\n";
  std::string random_bytes(8192, '\0');
  std::mt19937 rng(7);
  for (char& c : random_bytes) c = static_cast<char>(rng() & 0xff);
  const auto noise = dir / "noise.db";
  std::ofstream(noise, std::ios::binary) << random_bytes;
  for (const auto& path : {text, noise}) {
    const std::string before = fileContents(path);
    const std::string message = errorOf([&] { openSqliteStore(path); });
    EXPECT_NE(message.find(path.string()), std::string::npos) << message;
    EXPECT_NE(message.find("not a SQLite file"), std::string::npos) << message;
    EXPECT_EQ(fileContents(path), before);
  }
  const auto foreign = dir / "other.sqlite";
  rawExec(foreign, "CREATE TABLE things (x); INSERT INTO things VALUES (1);");
  std::string message = errorOf([&] { openSqliteStore(foreign); });
  EXPECT_NE(message.find("not a tessera texture database"), std::string::npos) << message;

  const std::string message_folder = errorOf([&] { openSqliteStore(dir.path()); });
  EXPECT_NE(message_folder.find("is a folder"), std::string::npos) << message_folder;
}

TEST(SqliteStore, RefusesACorruptDatabase) {
  TempFolder dir;
  const auto path = dir / "textures.db";
  openSqliteStore(path)->commit({{makeTexture(32)}, {}, {}});
  std::string bytes = fileContents(path);
  ASSERT_GT(bytes.size(), 4096u);
  // Keep the 100-byte header (so it still looks like tessera's); garble the schema page.
  for (std::size_t i = 100; i < 4096; ++i) bytes[i] = static_cast<char>(i * 37);
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
  const std::string message = errorOf([&] { openSqliteStore(path); });
  EXPECT_NE(message.find(path.string()), std::string::npos) << message;
  EXPECT_NE(message.find("corrupt"), std::string::npos) << message;
}

// A 0-byte file (touch, mktemp) is taken as a new database when creating is allowed, and
// refused otherwise.
TEST(SqliteStore, EmptyFileIsANewDatabaseOnlyWhenCreating) {
  TempFolder dir;
  const auto path = dir / "empty.db";
  std::ofstream(path).close();
  for (const OpenOptions& options : {OpenOptions{.create = false, .read_only = false},
                                    OpenOptions{.create = true, .read_only = true}}) {
    const std::string message = errorOf([&] { openSqliteStore(path, options); });
    EXPECT_NE(message.find("empty file"), std::string::npos) << message;
    EXPECT_EQ(std::filesystem::file_size(path), 0u);
  }
  auto store = openSqliteStore(path);
  store->commit({{makeTexture(33)}, {}, {}});
  EXPECT_EQ(store->stats().textures, 1u);
}

TEST(SqliteStore, ReadOnlyNeverCreatesNorWrites) {
  TempFolder dir;
  const auto path = dir / "missing.db";
  std::string message =
      errorOf([&] { openSqliteStore(path, {.create = true, .read_only = true}); });
  EXPECT_NE(message.find(path.string()), std::string::npos) << message;
  EXPECT_NE(message.find("no such texture database"), std::string::npos) << message;
  message = errorOf([&] { openSqliteStore(path, {.create = false, .read_only = false}); });
  EXPECT_NE(message.find("no such texture database"), std::string::npos) << message;
  EXPECT_TRUE(folderListing(dir.path()).empty());
  message = errorOf([&] { openSqliteStore(dir / "no_folder" / "t.db"); });
  EXPECT_NE(message.find("no folder"), std::string::npos) << message;

  const auto existing = dir / "textures.db";
  openSqliteStore(existing)->commit({{makeTexture(34)}, {}, {}});
  auto store = openSqliteStore(existing, {.create = false, .read_only = true});
  EXPECT_EQ(store->textures().size(), 1u);
  // The writer left the file alone (no -wal, -shm), and reading it adds none.
  EXPECT_EQ(folderListing(dir.path()), std::vector<std::string>{"textures.db"});
  message = errorOf([&] { store->beginRun("x"); });
  EXPECT_NE(message.find("read-only"), std::string::npos) << message;
  message = errorOf([&] { store->commit({{makeTexture(35)}, {}, {}}); });
  EXPECT_NE(message.find("read-only"), std::string::npos) << message;
}

TEST(SqliteStore, FinishingAnUnknownRunIsAnError) {
  TempFolder dir;
  auto store = openSqliteStore(dir / "textures.db");
  const std::string message = errorOf([&] { store->finishRun(42); });
  EXPECT_NE(message.find("no run 42"), std::string::npos) << message;
}

TEST(TextureStoreLocation, AnUnreachablePostgresServerIsOneClearErrorWithoutCredentials) {
  // Port 1 on the loopback refuses at once: no server is needed to see the message.
  const std::string message =
      errorOf([] { openTextureStore("postgresql://robot:secret@127.0.0.1:1/textures"); });
  EXPECT_NE(message.find("postgresql://robot@127.0.0.1:1/textures: cannot connect"),
            std::string::npos)
      << message;
  EXPECT_EQ(message.find("secret"), std::string::npos) << message;
  EXPECT_FALSE(errorOf([] { openTextureStore("postgres://127.0.0.1:1/t"); }).empty());
  TempFolder dir;
  EXPECT_EQ(openTextureStore((dir / "t.db").string())->stats().textures, 0u);
}

TEST(ContentKey, IsSixteenHexDigitsAndFollowsThePixels) {
  const TextureRecord a = makeTexture(40);
  const std::string key = contentKey(a.rgb, a.mask);
  EXPECT_EQ(key.size(), 16u);
  EXPECT_EQ(key.find_first_not_of("0123456789abcdef"), std::string::npos) << key;
  EXPECT_EQ(contentKey(a.rgb.clone(), a.mask.clone()), key);
  cv::Mat mask = a.mask.clone();
  mask.at<std::uint8_t>(0, 0) ^= 255;
  EXPECT_NE(contentKey(a.rgb, mask), key);
  cv::Mat rgb = a.rgb.clone();
  rgb.at<cv::Vec3b>(3, 3)[1] ^= 1;
  EXPECT_NE(contentKey(rgb, a.mask), key);
  // No mask means all valid.
  EXPECT_EQ(contentKey(a.rgb, cv::Mat()), contentKey(a.rgb, cv::Mat(a.rgb.size(), CV_8UC1, 255)));
  EXPECT_STREQ(kindName(TextureKind::kPattern), "pattern");
  EXPECT_STREQ(kindName(TextureKind::kSingle), "single");
}

}  // namespace
}  // namespace tessera::db::test
