// The SQLite texture store under a killed writer process and under concurrent readers.
#include <poll.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <mutex>
#include <thread>

#include <gtest/gtest.h>

#include "store_test_support.h"
#include "tessera/db/texture_store.h"

namespace tessera::db::test {
namespace {

// The whole of a stored texture is there: pixels that decode to the stored key, the CCV, one
// descriptor row per keypoint.
void expectComplete(const TextureStore& store, std::int64_t id, std::string& problem) {
  const auto t = store.texture(id);
  if (!t) {
    problem = "listed texture " + std::to_string(id) + " not found";
  } else if (t->rgb.empty() || t->ccv.size() != kCcvSize ||
             static_cast<std::size_t>(t->descriptors.rows) != t->keypoints.size() ||
             t->content_key != contentKey(t->rgb, t->mask)) {
    problem = "texture " + std::to_string(id) + " is incomplete";
  }
}

Commit oneTextureCommit(std::int64_t run, int patch, std::uint32_t seed) {
  Commit commit;
  commit.textures = {makeTexture(seed, 64, 48)};
  commit.textures[0].run_id = run;
  commit.textures[0].source_patch = patch;
  commit.instances.push_back({run, patch, 1, 0, -1, {}, std::nullopt, false});
  return commit;
}

// The child process: commits one texture and one instance at a time and reports the number of
// finished commits through `report_fd` after each. Never returns.
[[noreturn]] void commitUntilKilled(const std::filesystem::path& path, int report_fd) {
  try {
    auto store = openSqliteStore(path);
    const std::int64_t run = store->beginRun("crash test");
    for (std::int32_t done = 1; done < 100000; ++done) {
      store->commit(oneTextureCommit(run, done, static_cast<std::uint32_t>(done)));
      if (write(report_fd, &done, sizeof(done)) != static_cast<ssize_t>(sizeof(done))) _exit(2);
    }
  } catch (...) {
    _exit(3);
  }
  _exit(0);
}

// fork() with no other thread alive: gtest_discover_tests runs each test in its own process,
// and the other tests of this binary join their threads before they end.
TEST(SqliteStoreCrash, KilledWriterKeepsEveryFinishedCommitAndNothingHalfDone) {
  TempFolder dir;
  const auto path = dir / "crash.db";
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    close(fds[0]);
    commitUntilKilled(path, fds[1]);
  }
  close(fds[1]);

  std::int32_t reported = 0;
  const auto readReport = [&](int timeout_ms) {
    pollfd ready{fds[0], POLLIN, 0};
    if (poll(&ready, 1, timeout_ms) <= 0) return false;
    std::int32_t count = 0;
    if (read(fds[0], &count, sizeof(count)) != static_cast<ssize_t>(sizeof(count))) return false;
    reported = std::max(reported, count);
    return true;
  };
  while (reported < 20 && readReport(60000)) {
  }
  kill(child, SIGKILL);
  int status = 0;
  waitpid(child, &status, 0);
  while (readReport(0)) {  // reports written before the kill landed
  }
  close(fds[0]);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL)
      << "the writer ended by itself (status " << status << ") after " << reported << " commits";
  ASSERT_GE(reported, 20);

  EXPECT_EQ(rawQuery(path, "PRAGMA integrity_check"), "ok");
  auto store = openSqliteStore(path);
  const StoreStats stats = store->stats();
  // Every reported commit is there; at most the one whose report the kill cut off is extra.
  EXPECT_GE(stats.textures, static_cast<std::size_t>(reported));
  EXPECT_LE(stats.textures, static_cast<std::size_t>(reported) + 1);
  EXPECT_EQ(stats.instances, stats.textures);  // never a texture without its instance
  std::string problem;
  for (const CcvEntry& entry : store->ccvVectors()) {
    EXPECT_EQ(entry.ccv.size(), kCcvSize);
    expectComplete(*store, entry.id, problem);
    EXPECT_TRUE(problem.empty()) << problem;
  }
  // And the reopened store writes on.
  store->commit(oneTextureCommit(store->runs()[0].id, 0, 999999));
  EXPECT_EQ(store->stats().textures, stats.textures + 1);
}

// The child process: commits one texture, then runs into a file size limit (as it would into a
// full disk) half-way through writing a large one. Exits with 0 when that commit threw an error
// naming the database, stored nothing, and the store committed again afterwards.
[[noreturn]] void failAWriteHalfWay(const std::filesystem::path& path) {
  int result = 0;
  try {
    auto store = openSqliteStore(path);
    const std::int64_t run = store->beginRun("write failure");
    store->commit(oneTextureCommit(run, 1, 1));
    signal(SIGXFSZ, SIG_IGN);  // a write past the limit then fails (EFBIG) instead of killing
    rlimit limit{};
    getrlimit(RLIMIT_FSIZE, &limit);
    const rlimit unlimited = limit;
    limit.rlim_cur = std::max(std::filesystem::file_size(path),
                              std::filesystem::file_size(path.string() + "-wal")) +
                     16384;
    setrlimit(RLIMIT_FSIZE, &limit);
    Commit big = oneTextureCommit(run, 2, 2);
    big.textures[0] = makeTexture(2, 512, 512);  // random pixels: about 1 MB of PNG
    std::string message;
    try {
      store->commit(big);
    } catch (const core::Error& e) {
      message = e.what();
    }
    setrlimit(RLIMIT_FSIZE, &unlimited);
    std::fprintf(stderr, "the failed commit: %s\n", message.c_str());
    if (message.find(path.string()) == std::string::npos) {
      result = 11;
    } else if (store->stats().textures != 1 || store->instances().size() != 1) {
      result = 12;
    } else {
      store->commit(oneTextureCommit(run, 3, 3));
      result = store->stats().textures == 2 ? 0 : 13;
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s\n", e.what());
    result = 14;
  }
  _exit(result);
}

// In a child process, because the file size limit is process-wide.
TEST(SqliteStoreCrash, WriteFailureInACommitStoresNothingOfIt) {
  TempFolder dir;
  const auto path = dir / "full.db";
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) failAWriteHalfWay(path);
  int status = 0;
  waitpid(child, &status, 0);
  ASSERT_TRUE(WIFEXITED(status)) << "status " << status;
  EXPECT_EQ(WEXITSTATUS(status), 0) << "see failAWriteHalfWay for the code";
  EXPECT_EQ(rawQuery(path, "PRAGMA integrity_check"), "ok");
  EXPECT_EQ(openSqliteStore(path)->stats().textures, 2u);
}

TEST(SqliteStoreConcurrency, ReadersSeeCompleteTexturesWhileACommitIsWritten) {
  TempFolder dir;
  auto store = openSqliteStore(dir / "textures.db");
  const std::int64_t run = store->beginRun("concurrency");
  constexpr int kCommits = 50;
  std::atomic<bool> writing{true};
  std::mutex problems_mutex;
  std::vector<std::string> problems;
  const auto report = [&](const std::string& problem) {
    const std::lock_guard lock(problems_mutex);
    problems.push_back(problem);
  };

  std::thread writer([&] {
    try {
      for (int i = 0; i < kCommits; ++i) {
        store->commit(oneTextureCommit(run, i, static_cast<std::uint32_t>(1000 + i)));
      }
    } catch (const std::exception& e) {
      report(std::string("writer: ") + e.what());
    }
    writing = false;
  });
  std::atomic<int> reads{0};
  const auto readLoop = [&] {
    std::size_t seen = 0;
    try {
      do {
        const auto entries = store->ccvVectors();
        if (entries.size() < seen) report("the number of textures went down");
        seen = entries.size();
        for (const CcvEntry& entry : entries) {
          std::string problem;
          expectComplete(*store, entry.id, problem);
          if (!problem.empty()) report(problem);
        }
        if (store->textures().size() < seen) report("textures() lists fewer than ccvVectors()");
        ++reads;
      } while (writing);
    } catch (const std::exception& e) {
      report(std::string("reader: ") + e.what());
    }
  };
  std::thread reader_a(readLoop), reader_b(readLoop);
  writer.join();
  reader_a.join();
  reader_b.join();

  EXPECT_TRUE(problems.empty()) << problems.front();
  EXPECT_GE(reads.load(), 2);
  EXPECT_EQ(store->ccvVectors().size(), static_cast<std::size_t>(kCommits));
  EXPECT_EQ(store->instances(run).size(), static_cast<std::size_t>(kCommits));
}

}  // namespace
}  // namespace tessera::db::test
