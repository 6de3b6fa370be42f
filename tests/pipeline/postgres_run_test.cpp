// The pipeline on the default recording with its texture database on a PostgreSQL server (a
// throwaway one, support/postgres_cluster.h), against the same run with SQLite: the same
// textures and instances, even when the server is stopped mid-run; and the password, given in
// the URL, nowhere in what the run writes or logs.
#include <chrono>
#include <fstream>
#include <iterator>
#include <set>
#include <sstream>
#include <thread>
#include <tuple>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include "support/postgres_test.h"
#include "support/test_data.h"
#include "tessera/db/texture_store.h"
#include "tessera/drivers/oni/oni_source.h"
#include "tessera/pipeline/run.h"

namespace tessera::pipeline {
namespace {

namespace fs = std::filesystem;

using PostgresRun = test::PostgresTest;

// What a database holds, by content rather than by id (the two stores number alike only by
// chance): each texture's content key, and each instance with its texture's key.
struct Contents {
  std::set<std::string> textures;
  std::set<std::tuple<int, int, int, bool, std::string>> instances;
  bool operator==(const Contents&) const = default;
};

Contents contentsOf(const db::TextureStore& store) {
  Contents contents;
  std::map<std::int64_t, std::string> key_of;
  for (const db::TextureSummary& summary : store.textures()) {
    key_of[summary.id] = store.texture(summary.id)->content_key;
    contents.textures.insert(key_of[summary.id]);
  }
  for (const db::TextureInstance& i : store.instances()) {
    contents.instances.insert({i.patch_id, i.version, i.layer, i.reused, key_of[i.texture_id]});
  }
  return contents;
}

std::string everythingWritten(const fs::path& folder) {
  std::string all;
  for (const auto& entry : fs::recursive_directory_iterator(folder)) {
    if (!entry.is_regular_file()) continue;
    std::ifstream in(entry.path(), std::ios::binary);
    all.append(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  return all;
}

TEST_F(PostgresRun, AServerStoppedMidRunLosesNothingAndNoPasswordIsWrittenOrLogged) {
  const fs::path recording = test::sourceDir() / "recordings/office.oni";
  if (!fs::is_regular_file(recording)) {
    GTEST_SKIP() << "recordings/office.oni not rendered (configure with "
                    "TESSERA_RENDER_DEFAULT_RECORDING=ON)";
  }
  const auto replay = [&](const std::string& db, const fs::path& out,
                          StatsSink::ProgressCallback on_progress) {
    drivers::oni::OniSource source(recording);
    RunOptions options;
    options.out_dir = out;
    options.poses = PoseSource::kGroundTruth;
    options.db = db;
    options.on_progress = std::move(on_progress);
    return runPipeline(source, loadRunConfig(std::nullopt), options);
  };

  const fs::path sqlite_out = test::freshTempDir();
  replay((sqlite_out / "textures.db").string(), sqlite_out, {});
  const Contents expected = contentsOf(*db::openSqliteStore(sqlite_out / "textures.db"));
  ASSERT_GE(expected.textures.size(), 10u);

  // The password in the URL this time, where a careless log line would show it.
  const std::string url = freshDatabase();
  const std::string password = test::PostgresCluster::password();
  const std::string with_password = "postgresql://tessera:" + password + url.substr(20);
  std::ostringstream log;
  const auto capture = std::make_shared<spdlog::sinks::ostream_sink_mt>(log);
  spdlog::default_logger()->sinks().push_back(capture);
  // From frame 200 of 320 the server is down for 4 s: patches finalised then, and those the
  // end of the stream finalises, wait in the journal.
  std::thread outage;
  const fs::path pg_out = test::freshTempDir();
  const RunSummary summary = replay(with_password, pg_out, [&](const Progress& progress) {
    if (progress.frames_done != 200 || outage.joinable()) return;
    outage = std::thread([&] {
      cluster_->stopServer();
      std::this_thread::sleep_for(std::chrono::seconds(4));
      cluster_->startServer();
    });
  });
  if (outage.joinable()) outage.join();
  spdlog::default_logger()->sinks().pop_back();

  ASSERT_TRUE(summary.database.server_link);
  const db::ServerLink& link = *summary.database.server_link;
  EXPECT_EQ(link.outages, 1u);
  EXPECT_GE(link.replayed_commits, 1u);
  EXPECT_EQ(link.pending_commits, 0u);
  EXPECT_EQ(link.refused_commits, 0u);
  EXPECT_GT(link.disconnected_s, 0.5);
  EXPECT_EQ(summary.commits.commit_failures, 0u);
  EXPECT_FALSE(fs::exists(pg_out / "db_journal.sqlite"));  // emptied, then removed

  const auto store = db::openTextureStore(url, {.create = false, .read_only = true});
  const Contents stored = contentsOf(*store);
  EXPECT_EQ(stored.textures, expected.textures);
  EXPECT_EQ(stored.instances, expected.instances);
  // The map names the server's ids, not the provisional ones.
  nlohmann::json report;
  std::ifstream(pg_out / "report.json") >> report;
  EXPECT_EQ(report["db_server"]["outages"], 1);
  const std::string patches = everythingWritten(pg_out);
  EXPECT_EQ(patches.find("texture_2814749767"), std::string::npos);  // 2^48 and up

  EXPECT_EQ(everythingWritten(pg_out).find(password), std::string::npos);
  EXPECT_EQ(log.str().find(password), std::string::npos);
  EXPECT_NE(log.str().find("commits wait in"), std::string::npos) << log.str();
}

}  // namespace
}  // namespace tessera::pipeline
