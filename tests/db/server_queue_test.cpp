// The queue a server's store keeps while its server is away (queueWhileAway), against a
// stand-in server: an SQLite store that can be switched "away", when every call throws
// ServerUnavailable as the PostgreSQL store does. No server process is needed; the same queue
// in front of a real PostgreSQL server is tested in postgres_store_test.cpp.
#include <atomic>
#include <chrono>
#include <memory>
#include <thread>

#include <opencv2/core.hpp>

#include "db/store_test_support.h"
#include "tessera/db/texture_store.h"

namespace tessera::db {
namespace {

using test::errorOf;
using test::makeTexture;
using test::TempFolder;

// Provisional ids start at 2^48; a test database's ids stay far below 2^40.
constexpr std::int64_t kSmallId = std::int64_t{1} << 40;

class StandInServer final : public TextureStore {
 public:
  StandInServer(const std::filesystem::path& file, std::string name,
                std::shared_ptr<std::atomic<bool>> away)
      : inner_(openSqliteStore(file)), name_(std::move(name)), away_(std::move(away)) {}

  std::string location() const override { return name_; }
  std::int64_t beginRun(const std::string& source) override {
    return reachable().beginRun(source);
  }
  void finishRun(std::int64_t run_id) override { reachable().finishRun(run_id); }
  std::vector<std::int64_t> commit(const Commit& commit) override {
    return reachable().commit(commit);
  }
  std::vector<std::int64_t> removeUnused(std::int64_t run_id,
                                         const std::vector<std::int64_t>& candidates) override {
    return reachable().removeUnused(run_id, candidates);
  }
  std::optional<std::int64_t> findByContentKey(const std::string& key) const override {
    return reachable().findByContentKey(key);
  }
  std::optional<TextureRecord> texture(std::int64_t id) const override {
    return reachable().texture(id);
  }
  std::vector<CcvEntry> ccvVectors(std::int64_t after_id) const override {
    return reachable().ccvVectors(after_id);
  }
  std::vector<TextureSummary> textures() const override { return reachable().textures(); }
  std::vector<TextureInstance> instances(std::optional<std::int64_t> run_id) const override {
    return reachable().instances(run_id);
  }
  std::vector<RunRecord> runs() const override { return reachable().runs(); }
  StoreStats stats() const override { return reachable().stats(); }

 private:
  TextureStore& reachable() const {
    if (*away_) throw ServerUnavailable(name_ + ": cannot connect: stand-in server is away");
    return *inner_;
  }
  std::unique_ptr<TextureStore> inner_;
  std::string name_;
  std::shared_ptr<std::atomic<bool>> away_;
};

class ServerQueueTest : public ::testing::Test {
 protected:
  std::unique_ptr<TextureStore> open(const std::string& name = "standin://fleet",
                                     double finish_wait_s = 10.0, std::size_t max_mb = 64) {
    OpenOptions options;
    options.journal = dir_ / "journal.sqlite";
    options.finish_wait_s = finish_wait_s;
    options.journal_max_mb = max_mb;
    return queueWhileAway(std::make_unique<StandInServer>(dir_ / "server.db", name, away_),
                          options);
  }
  // What the server holds, read directly.
  std::unique_ptr<TextureStore> server() { return openSqliteStore(dir_ / "server.db"); }

  static bool sentWithin(const TextureStore& store, std::chrono::seconds limit) {
    const auto deadline = std::chrono::steady_clock::now() + limit;
    while (std::chrono::steady_clock::now() < deadline) {
      if (store.serverLink()->pending_commits == 0) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return false;
  }

  TempFolder dir_;
  std::shared_ptr<std::atomic<bool>> away_ = std::make_shared<std::atomic<bool>>(false);
};

TextureInstance instanceOf(std::int64_t run, int patch, int version, std::int64_t texture_id) {
  TextureInstance i;
  i.run_id = run;
  i.patch_id = patch;
  i.version = version;
  i.texture_id = texture_id;
  i.transform = core::Similarity2::fromAngleScale(0.05 * patch, 1.0, 1.0, 2.0);
  return i;
}

TEST_F(ServerQueueTest, CommitsMadeWhileTheServerIsAwayAreSentInOrderWhenItIsBack) {
  const auto store = open();
  const std::int64_t run = store->beginRun("office");
  Commit first;
  first.textures = {makeTexture(1)};
  first.instances = {instanceOf(run, 1, 1, -1), instanceOf(run, 2, 1, -1)};
  const std::int64_t t1 = store->commit(first).at(0);
  EXPECT_LT(t1, kSmallId);

  *away_ = true;
  Commit second;  // a new texture while away: a provisional id
  second.textures = {makeTexture(2)};
  second.instances = {instanceOf(run, 3, 1, -1)};
  const std::int64_t t2 = store->commit(second).at(0);
  EXPECT_GE(t2, kSmallId);
  Commit third;  // reuses the queued texture by its provisional id; patch 1 gets a version 2
  third.textures = {makeTexture(3)};
  third.instances = {instanceOf(run, 4, 1, t2), instanceOf(run, 1, 2, -1)};
  third.retired = {{run, 2}};
  const std::int64_t t3 = store->commit(third).at(0);

  // The queued texture reads back from the journal, and is found by its pixels.
  const auto queued = store->texture(t2);
  ASSERT_TRUE(queued);
  EXPECT_EQ(cv::norm(queued->rgb, makeTexture(2).rgb, cv::NORM_INF), 0.0);
  EXPECT_EQ(store->findByContentKey(contentKey(queued->rgb, queued->mask)), t2);
  const ServerLink away = *store->serverLink();
  EXPECT_EQ(away.outages, 1u);
  EXPECT_EQ(away.queued_commits, 2u);
  EXPECT_EQ(away.pending_commits, 2u);
  // Nothing reached the server meanwhile (checked before it is back: once it is, the store's
  // sender may deliver the queue at any moment).
  EXPECT_EQ(server()->stats().textures, 1u);
  *away_ = false;

  ASSERT_TRUE(sentWithin(*store, std::chrono::seconds(10)));
  const std::int64_t s2 = store->resolvedId(t2), s3 = store->resolvedId(t3);
  EXPECT_LT(s2, kSmallId);
  EXPECT_LT(s3, kSmallId);
  EXPECT_NE(s2, s3);
  std::map<int, std::pair<int, std::int64_t>> shown;  // patch -> (version, texture)
  for (const TextureInstance& i : server()->instances()) shown[i.patch_id] = {i.version, i.texture_id};
  const std::map<int, std::pair<int, std::int64_t>> expected = {
      {1, {2, s3}}, {3, {1, s2}}, {4, {1, s2}}};  // patch 2 retired
  EXPECT_EQ(shown, expected);
  const ServerLink back = *store->serverLink();
  EXPECT_EQ(back.replayed_commits, 2u);
  EXPECT_EQ(back.replayed_textures, 2u);
  EXPECT_GT(back.disconnected_s, 0.0);
  EXPECT_EQ(back.refused_commits, 0u);

  // Once sent, a provisional id still reads, and commits go straight to the server again.
  ASSERT_TRUE(store->texture(t2));
  Commit fourth;
  fourth.textures = {makeTexture(4)};
  fourth.instances = {instanceOf(run, 5, 1, t3)};
  EXPECT_LT(store->commit(fourth).at(0), kSmallId);
  store->finishRun(run);
  EXPECT_TRUE(server()->runs().at(0).finished);
  EXPECT_EQ(server()->stats().textures, 4u);
}

TEST_F(ServerQueueTest, UnusedTexturesAreRemovedOnlyOnceTheServerHasEveryCommit) {
  const auto store = open();
  const std::int64_t run = store->beginRun("office");
  const auto version = [&](int v, std::uint32_t seed) {
    Commit commit;
    commit.textures = {makeTexture(seed)};
    commit.textures[0].run_id = run;
    commit.instances = {instanceOf(run, 1, v, -1)};
    return store->commit(commit).at(0);
  };
  const std::int64_t first = version(1, 21);
  *away_ = true;
  const std::int64_t second = version(2, 22);  // queued: a provisional id
  EXPECT_TRUE(store->removeUnused(run, {first}).empty());
  *away_ = false;
  ASSERT_TRUE(sentWithin(*store, std::chrono::seconds(10)));
  const std::int64_t third = version(3, 23);
  // The caller's ids come back, the provisional one included.
  EXPECT_EQ(store->removeUnused(run, {second, first}), (std::vector<std::int64_t>{first, second}));
  EXPECT_EQ(server()->stats().textures, 1u);
  version(4, 24);
  *away_ = true;  // away with an empty queue: nothing removed now, and no outage counted
  EXPECT_TRUE(store->removeUnused(run, {third}).empty());
  EXPECT_EQ(store->serverLink()->outages, 1u);
  EXPECT_EQ(server()->stats().textures, 2u);
  *away_ = false;
  // What had to wait (the first version, since removed, and the third) goes at the run's end.
  store->finishRun(run);
  EXPECT_EQ(server()->stats().textures, 1u);
  EXPECT_EQ(store->serverLink()->removed_at_end, 1u);
}

TEST_F(ServerQueueTest, ARunEndingWhileTheServerIsAwayLeavesItsCommitsForTheNextOpen) {
  std::int64_t run = 0;
  {
    const auto store = open("standin://fleet", 0.2);
    run = store->beginRun("office");
    *away_ = true;
    Commit commit;
    commit.textures = {makeTexture(7)};
    commit.instances = {instanceOf(run, 1, 1, -1)};
    store->commit(commit);
    store->finishRun(run);  // waits 0.2 s, then queues the run's end too
    EXPECT_EQ(store->serverLink()->pending_commits, 2u);
  }
  EXPECT_TRUE(std::filesystem::exists(dir_ / "journal.sqlite"));
  *away_ = false;
  {
    const auto store = open();
    ASSERT_TRUE(sentWithin(*store, std::chrono::seconds(10)));
  }
  EXPECT_FALSE(std::filesystem::exists(dir_ / "journal.sqlite"));  // empty: removed
  EXPECT_EQ(server()->stats().textures, 1u);
  EXPECT_EQ(server()->instances().size(), 1u);
  EXPECT_TRUE(server()->runs().at(0).finished);
}

TEST_F(ServerQueueTest, AJournalOfAnotherServerIsRefused) {
  {
    const auto store = open("standin://fleet", 0.1);
    const std::int64_t run = store->beginRun("office");
    *away_ = true;
    Commit commit;
    commit.instances = {instanceOf(run, 1, 1, 1)};
    store->commit(commit);
  }
  const std::string message = errorOf([&] { open("standin://other"); });
  EXPECT_NE(message.find("journal.sqlite: holds commits for standin://fleet, not for "
                         "standin://other"),
            std::string::npos)
      << message;
}

TEST_F(ServerQueueTest, AFullJournalRefusesTheCommitAndKeepsTheEarlierOnes) {
  const auto store = open("standin://fleet", 10.0, /*max_mb=*/1);
  const std::int64_t run = store->beginRun("office");
  *away_ = true;
  // Random pixels do not compress: 700 x 600 RGB is about 1.2 MB of PNG.
  Commit big;
  big.textures = {makeTexture(11, 700, 600)};
  big.instances = {instanceOf(run, 1, 1, -1)};
  store->commit(big);
  Commit more = big;
  more.textures = {makeTexture(12, 700, 600)};
  more.instances = {instanceOf(run, 2, 1, -1)};
  const std::string message = errorOf([&] { store->commit(more); });
  EXPECT_NE(message.find("the commit journal is full (1 MB)"), std::string::npos) << message;
  *away_ = false;
  ASSERT_TRUE(sentWithin(*store, std::chrono::seconds(10)));
  EXPECT_EQ(server()->stats().textures, 1u);
  EXPECT_EQ(server()->instances().at(0).patch_id, 1);
}

TEST_F(ServerQueueTest, AQueuedCommitTheServerRefusesIsDroppedAndTheRestIsSent) {
  const auto store = open();
  const std::int64_t run = store->beginRun("office");
  *away_ = true;
  Commit bad;  // names a texture the server does not have
  bad.instances = {instanceOf(run, 1, 1, 999)};
  store->commit(bad);
  Commit good;
  good.textures = {makeTexture(21)};
  good.instances = {instanceOf(run, 2, 1, -1)};
  store->commit(good);
  *away_ = false;
  ASSERT_TRUE(sentWithin(*store, std::chrono::seconds(10)));
  const ServerLink link = *store->serverLink();
  EXPECT_EQ(link.refused_commits, 1u);
  EXPECT_EQ(link.replayed_commits, 1u);
  ASSERT_EQ(server()->instances().size(), 1u);
  EXPECT_EQ(server()->instances().at(0).patch_id, 2);
}

}  // namespace
}  // namespace tessera::db
