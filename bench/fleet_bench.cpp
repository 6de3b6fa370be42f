// A fleet's texture database on PostgreSQL, on this machine, against a throwaway server
// (initdb + pg_ctl, as the tests use):
//   1. one replay of the default recording (the reference);
//   2. N replays at once into one database, as N robots: the textures the database ends with
//      (the reference's, once), every instance, and each run's database commit time p95;
//      the same into one SQLite file for comparison;
//   3. one replay with the server stopped for --outage-s seconds mid-run: what waited in the
//      journal and whether the database ends as the reference;
//   4. the reads matching makes, at --textures textures, PostgreSQL against SQLite: loading
//      the CCV index, a texture by id, a texture by content key.
// Prints figures; never fails on a slow machine (a missing server or recording is an error).
#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <random>
#include <set>
#include <thread>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "../tests/support/postgres_cluster.h"
#include "tessera/db/texture_store.h"

namespace {

namespace fs = std::filesystem;
using tessera::test::PostgresCluster;
using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

double percentile(std::vector<double> values, double p) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  return values[static_cast<std::size_t>(p * static_cast<double>(values.size() - 1))];
}

nlohmann::json readReport(const fs::path& out) {
  nlohmann::json report;
  std::ifstream(out / "report.json") >> report;
  return report;
}

// One `tessera run` of the default recording; its report.
nlohmann::json replay(const std::string& db, const fs::path& out) {
  fs::remove_all(out);
  const std::string command =
      fmt::format("{} run {}/recordings/office.oni --quiet --db '{}' --out {} > {}.log 2>&1",
                  TESSERA_BINARY, TESSERA_SOURCE_DIR, db, out.string(), out.string());
  if (std::system(command.c_str()) != 0) {
    throw std::runtime_error("tessera run failed: see " + out.string() + ".log");
  }
  return readReport(out);
}

std::unique_ptr<tessera::db::TextureStore> openToRead(const std::string& location) {
  tessera::db::OpenOptions options;
  options.create = false;
  options.read_only = true;
  return tessera::db::openTextureStore(location, options);
}

// The database's textures by content key, and its instance count.
std::pair<std::set<std::string>, std::size_t> contentsOf(const std::string& location) {
  const auto store = openToRead(location);
  std::set<std::string> keys;
  for (const auto& t : store->textures()) keys.insert(store->texture(t.id)->content_key);
  return {keys, store->instances().size()};
}

// Runs whose instances in the database are not the ones their map committed.
std::size_t runsMissingInstances(const std::string& location,
                                 const std::vector<nlohmann::json>& reports) {
  const auto store = openToRead(location);
  std::size_t missing = 0;
  for (const nlohmann::json& r : reports) {
    const std::size_t stored = store->instances(r["db_run_id"].get<std::int64_t>()).size();
    missing += stored == r["db_instances"].get<std::size_t>() ? 0 : 1;
  }
  return missing;
}

void concurrentReplays(PostgresCluster& cluster, int replays, const fs::path& work,
                       const std::set<std::string>& reference) {
  for (const bool postgres : {true, false}) {
    for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(work / ("fleet.db" + std::string(suffix)));
    const std::string db = postgres ? (cluster.createDatabase("fleet"), cluster.url("fleet"))
                                    : (work / "fleet.db").string();
    const auto start = Clock::now();
    std::vector<std::thread> robots;
    std::vector<nlohmann::json> reports(static_cast<std::size_t>(replays));
    for (int i = 0; i < replays; ++i) {
      robots.emplace_back([&, i] {
        reports[static_cast<std::size_t>(i)] =
            replay(db, work / fmt::format("{}_robot{}", postgres ? "pg" : "sqlite", i));
      });
    }
    for (std::thread& robot : robots) robot.join();
    const double wall_s = msSince(start) / 1e3;
    fmt::print("\n{} replays at once into {} ({:.1f} s):\n", replays,
               postgres ? "one PostgreSQL database" : "one SQLite file", wall_s);
    double worst_p95 = 0.0;
    std::size_t failures = 0;
    for (int i = 0; i < replays; ++i) {
      const nlohmann::json& r = reports[static_cast<std::size_t>(i)];
      fmt::print("  robot {}: {:.1f} frames/s, {} textures stored, db commit p50 {:.1f} ms, "
                 "p95 {:.1f} ms, {} commit failures\n",
                 i, r["fps"].get<double>(), r["textures_stored"].get<int>(),
                 r["db_commit_ms_p50"].get<double>(), r["db_commit_ms_p95"].get<double>(),
                 r["commit_failures"].get<int>());
      worst_p95 = std::max(worst_p95, r["db_commit_ms_p95"].get<double>());
      failures += r["commit_failures"].get<std::size_t>();
    }
    const auto [keys, instances] = contentsOf(db);
    std::size_t new_to_fleet = 0;
    for (const std::string& key : keys) new_to_fleet += reference.count(key) ? 0 : 1;
    fmt::print("  database: {} textures, {} of them not among one replay's {} (robots reuse "
               "each other's textures mid-run, so their decisions differ); {} instances; "
               "runs whose committed instances are not all stored: {}; worst db commit p95 "
               "{:.1f} ms; {} commit failures\n",
               keys.size(), new_to_fleet, reference.size(), instances,
               runsMissingInstances(db, reports), worst_p95, failures);
    // The next day's robot: the same rooms again, into the fleet's database.
    const nlohmann::json next = replay(db, work / fmt::format("{}_next_day", postgres ? "pg" : "sqlite"));
    fmt::print("  one more replay afterwards: {} new textures stored, {} of {} patches reuse "
               "a stored texture, db commit p95 {:.1f} ms\n",
               next["textures_stored"].get<int>(), next["reuses"].get<int>(),
               next["textured_patches"].get<int>(), next["db_commit_ms_p95"].get<double>());
  }
}

void outage(PostgresCluster& cluster, double outage_s, const fs::path& work,
            const std::set<std::string>& reference, std::size_t reference_instances) {
  cluster.createDatabase("outage");
  const std::string url = cluster.url("outage");
  std::atomic<bool> done = false;
  // Stops the server once the run has committed a texture, for outage_s.
  std::thread saboteur([&] {
    while (!done) {
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
      try {
        if (contentsOf(url).first.empty()) continue;
      } catch (const std::exception&) {
        continue;  // the schema is not there yet
      }
      cluster.stopServer();
      std::this_thread::sleep_for(std::chrono::duration<double>(outage_s));
      cluster.startServer();
      return;
    }
  });
  const nlohmann::json report = replay(url, work / "pg_outage");
  done = true;
  saboteur.join();
  const nlohmann::json& link = report["db_server"];
  const auto [keys, instances] = contentsOf(url);
  fmt::print("\nOne replay, the server stopped for {:.0f} s mid-run:\n  {} outage(s), {:.1f} s "
             "disconnected, {} commits queued, {} replayed with {} textures, {} refused, {} "
             "left; {} commit failures; {:.1f} frames/s\n  database: {} textures ({}), {} "
             "instances ({} expected)\n",
             outage_s, link["outages"].get<int>(), link["disconnected_s"].get<double>(),
             link["queued_commits"].get<int>(), link["replayed_commits"].get<int>(),
             link["replayed_textures"].get<int>(), link["refused_commits"].get<int>(),
             link["pending_commits"].get<int>(), report["commit_failures"].get<int>(),
             report["fps"].get<double>(), keys.size(),
             keys == reference ? "the same as without the outage" : "DIFFERENT", instances,
             reference_instances);
}

// Fills `store` with `count` small random textures (commits of 500); their content keys.
std::vector<std::string> fill(tessera::db::TextureStore& store, std::size_t count) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> real(0.0f, 1.0f);
  cv::theRNG().state = 7;
  std::vector<std::string> keys;
  const std::int64_t run = store.beginRun("fleet_bench");
  tessera::db::Commit commit;
  for (std::size_t i = 0; i < count; ++i) {
    tessera::db::TextureRecord t;
    t.rgb.create(16, 16, CV_8UC3);
    cv::randu(t.rgb, 0, 256);
    t.texel_m = 0.005;
    for (int c = 0; c < 48; ++c) t.ccv.push_back(real(rng));
    t.run_id = run;
    keys.push_back(tessera::db::contentKey(t.rgb, t.mask));
    commit.textures.push_back(std::move(t));
    if (commit.textures.size() == 500 || i + 1 == count) {
      store.commit(commit);
      commit = {};
    }
  }
  store.finishRun(run);
  return keys;
}

struct ReadFigures {
  double fill_s = 0, index_ms = 0, by_id_p50 = 0, by_id_p95 = 0, by_key_p50 = 0, by_key_p95 = 0;
};

ReadFigures readLatency(tessera::db::TextureStore& store, std::size_t count) {
  ReadFigures f;
  auto start = Clock::now();
  const std::vector<std::string> keys = fill(store, count);
  f.fill_s = msSince(start) / 1e3;
  start = Clock::now();
  const auto index = store.ccvVectors(0);
  f.index_ms = msSince(start);
  std::mt19937 rng(11);
  std::uniform_int_distribution<std::size_t> pick(0, index.size() - 1);
  std::vector<double> by_id, by_key;
  for (int i = 0; i < 1000; ++i) {
    const auto& entry = index[pick(rng)];
    start = Clock::now();
    store.texture(entry.id);
    by_id.push_back(msSince(start));
    start = Clock::now();
    store.findByContentKey(keys[pick(rng)]);
    by_key.push_back(msSince(start));
  }
  f.by_id_p50 = percentile(by_id, 0.5);
  f.by_id_p95 = percentile(by_id, 0.95);
  f.by_key_p50 = percentile(by_key, 0.5);
  f.by_key_p95 = percentile(by_key, 0.95);
  return f;
}

void matchReads(PostgresCluster& cluster, std::size_t count, const fs::path& work) {
  cluster.createDatabase("many");
  fs::remove(work / "many.db");
  const auto sqlite = tessera::db::openSqliteStore(work / "many.db");
  const ReadFigures s = readLatency(*sqlite, count);
  const auto postgres = tessera::db::openTextureStore(cluster.url("many"));
  const ReadFigures p = readLatency(*postgres, count);
  fmt::print("\nThe reads matching makes, at {} textures (PostgreSQL / SQLite):\n", count);
  fmt::print("  filling (commits of 500): {:.1f} s / {:.1f} s\n", p.fill_s, s.fill_s);
  fmt::print("  CCV index load: {:.0f} ms / {:.0f} ms ({:.2f}x)\n", p.index_ms, s.index_ms,
             p.index_ms / s.index_ms);
  fmt::print("  texture by id: p50 {:.3f} / {:.3f} ms ({:.2f}x), p95 {:.3f} / {:.3f} ms\n",
             p.by_id_p50, s.by_id_p50, p.by_id_p50 / s.by_id_p50, p.by_id_p95, s.by_id_p95);
  fmt::print("  texture by content key: p50 {:.3f} / {:.3f} ms ({:.2f}x), p95 {:.3f} / {:.3f} "
             "ms\n",
             p.by_key_p50, s.by_key_p50, p.by_key_p50 / s.by_key_p50, p.by_key_p95,
             s.by_key_p95);
  // A run loads the CCV index once, then per patch at most match.max_candidates (4) textures
  // not yet cached and one key look-up; the per-patch database time when none is cached:
  const double pg_patch = 4 * p.by_id_p50 + p.by_key_p50;
  const double sqlite_patch = 4 * s.by_id_p50 + s.by_key_p50;
  fmt::print("  per patch matched (4 candidates + 1 key): {:.2f} / {:.2f} ms ({:.2f}x)\n",
             pg_patch, sqlite_patch, pg_patch / sqlite_patch);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"PostgreSQL for a fleet: concurrent replays, a server outage, reads at scale"};
  int replays = 4;
  double outage_s = 10.0;
  std::size_t textures = 100000;
  std::string work = "/tmp/tessera_fleet_bench";
  app.add_option("--replays", replays, "Replays at once")->capture_default_str();
  app.add_option("--outage-s", outage_s, "Seconds the server is stopped")->capture_default_str();
  app.add_option("--textures", textures, "Textures for the read figures (0: skip)")
      ->capture_default_str();
  app.add_option("--work", work, "Folder for outputs")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    std::string why_not;
    const auto cluster = PostgresCluster::start(why_not);
    if (!cluster) {
      fmt::print(stderr, "fleet_bench: {}\n", why_not);
      return 1;
    }
    setenv("PGPASSWORD", PostgresCluster::password(), 1);
    fs::create_directories(work);
    cluster->createDatabase("single");
    const nlohmann::json single = replay(cluster->url("single"), fs::path(work) / "pg_single");
    const auto [reference, reference_instances] = contentsOf(cluster->url("single"));
    fmt::print("One replay into PostgreSQL: {:.1f} frames/s, {} textures, {} instances, db "
               "commit p50 {:.1f} ms, p95 {:.1f} ms\n",
               single["fps"].get<double>(), reference.size(), reference_instances,
               single["db_commit_ms_p50"].get<double>(), single["db_commit_ms_p95"].get<double>());
    if (replays > 0) concurrentReplays(*cluster, replays, work, reference);
    if (outage_s > 0) outage(*cluster, outage_s, work, reference, reference_instances);
    if (textures > 0) matchReads(*cluster, textures, work);
  } catch (const std::exception& e) {
    fmt::print(stderr, "fleet_bench: {}\n", e.what());
    return 1;
  }
  return 0;
}
