// MapMonitor: what it gathers, its Prometheus exposition checked by the reference parser
// (python3-prometheus-client), and its history bounded on long runs.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tessera/pipeline/map_monitor.h"

namespace tessera::pipeline {
namespace {

namespace fs = std::filesystem;

// 40 frames at 20 frames/s, then two commits.
void feed(MapMonitor& monitor) {
  monitor.start("recordings/office.oni");
  for (std::size_t i = 1; i <= 40; ++i) {
    MonitorFrame frame;
    frame.elapsed_s = 0.05 * static_cast<double>(i);
    frame.frames_done = i;
    frame.frames_total = 320;
    frame.figures.tracking_ms = 8.0;
    frame.figures.integration_ms = 11.0;
    frame.figures.planes_ms = 14.0;
    frame.figures.tsdf_bytes = 1000 * i;
    frame.bitmap_bytes = 300;
    frame.map_bytes = 1000 * i + 300;
    frame.figures.patches_live = 3;
    frame.figures.patches_finalized = i / 10;
    monitor.onFrame(frame);
  }
  MonitorCommit commit;
  commit.committed = true;
  commit.reused = true;
  commit.patch.bitmap_ms = 120.0;
  commit.patch.match_ms = 40.0;
  commit.patch.commit_latency_ms = 300.0;
  commit.patch.ccv_considered = 10;
  commit.patch.ccv_removed = 8;
  commit.textures_stored = 2;
  commit.patterns_stored = 1;
  commit.economy.textured_patches = 3;
  commit.economy.reuses = 1;
  commit.economy.pixels_before = 3000;
  commit.economy.pixels_after = 1500;
  monitor.onCommit(commit);
  commit.patch.ccv_considered = 5;
  commit.patch.ccv_removed = 1;
  monitor.onCommit(commit);
}

TEST(MapMonitor, GathersFramesAndCommitsUnderReportJsonNames) {
  MapMonitor monitor;
  feed(monitor);
  const nlohmann::json stats = toJson(monitor.snapshot());
  EXPECT_EQ(stats["state"], "running");
  EXPECT_EQ(stats["frames"], 40);
  EXPECT_EQ(stats["frames_total"], 320);
  EXPECT_NEAR(stats["fps"].get<double>(), 20.0, 1e-9);
  EXPECT_EQ(stats["map_bytes"], 40300);
  EXPECT_EQ(stats["patches_finalized"], 4);
  EXPECT_EQ(stats["patches_committed"], 2);
  EXPECT_EQ(stats["textures_stored"], 2);
  EXPECT_EQ(stats["bytes_before"], 9000);
  EXPECT_EQ(stats["bytes_after"], 4500);
  EXPECT_NEAR(stats["compression"].get<double>(), 2.0, 1e-12);
  // CCV counts add up over commits: 9 of 15 removed.
  EXPECT_EQ(stats["ccv_considered"], 15);
  EXPECT_NEAR(stats["ccv_rejection"].get<double>(), 0.6, 1e-12);
  EXPECT_NEAR(stats["stage_ms"]["tracking"].get<double>(), 8.0, 1e-9);
  EXPECT_FALSE(stats.contains("report"));
}

TEST(MapMonitor, AFinishedRunCarriesItsReport) {
  MapMonitor monitor;
  feed(monitor);
  const std::uint64_t before = monitor.snapshot().generation;
  monitor.finish({{"frames", 40}, {"fps", 19.5}});
  const nlohmann::json stats = toJson(monitor.snapshot());
  EXPECT_EQ(stats["state"], "finished");
  EXPECT_EQ(stats["report"]["fps"], 19.5);
  EXPECT_GT(monitor.waitPast(before, std::chrono::milliseconds(0)), before);
}

// The exposition is parsed by the Prometheus project's own Python client, which refuses
// malformed lines, bad types and duplicate families.
TEST(MapMonitor, MetricsParseAsPrometheusExpositionWithTypesAndUnits) {
  // Debian's interpreter, whose packages python3-prometheus-client installs into.
  if (std::system("/usr/bin/python3 -c 'import prometheus_client' 2>/dev/null") != 0) {
    GTEST_SKIP() << "python3-prometheus-client is not installed (apt-get install "
                    "python3-prometheus-client): no reference parser to check against";
  }
  const fs::path dir = fs::temp_directory_path() / "tessera_metrics_test";
  fs::create_directories(dir);
  MapMonitor monitor;
  feed(monitor);
  { std::ofstream(dir / "metrics.txt") << toPrometheus(monitor.snapshot()); }
  const std::string script =
      "import json, sys\n"
      "from prometheus_client.parser import text_string_to_metric_families\n"
      "out = {}\n"
      "for f in text_string_to_metric_families(open(sys.argv[1]).read()):\n"
      "    out[f.name] = {'type': f.type, 'unit': f.unit, 'samples': "
      "[[s.name, s.labels, s.value] for s in f.samples]}\n"
      "json.dump(out, open(sys.argv[2], 'w'))\n";
  { std::ofstream(dir / "parse.py") << script; }
  const std::string command = "/usr/bin/python3 " + (dir / "parse.py").string() + " " +
                              (dir / "metrics.txt").string() + " " +
                              (dir / "parsed.json").string();
  ASSERT_EQ(std::system(command.c_str()), 0) << "the parser refused " << dir / "metrics.txt";
  nlohmann::json parsed;
  std::ifstream(dir / "parsed.json") >> parsed;
  // Counters are families without their _total suffix.
  ASSERT_TRUE(parsed.contains("tessera_frames"));
  EXPECT_EQ(parsed["tessera_frames"]["type"], "counter");
  EXPECT_EQ(parsed["tessera_frames"]["samples"][0][0], "tessera_frames_total");
  EXPECT_EQ(parsed["tessera_frames"]["samples"][0][2], 40.0);
  EXPECT_EQ(parsed["tessera_map_bytes"]["type"], "gauge");
  EXPECT_EQ(parsed["tessera_map_bytes"]["samples"][0][2], 40300.0);
  EXPECT_EQ(parsed["tessera_ccv_rejected"]["samples"][0][2], 9.0);
  // Times in seconds, labelled by stage.
  bool tracking = false;
  for (const auto& sample : parsed["tessera_stage_seconds"]["samples"]) {
    if (sample[1]["stage"] == "tracking") {
      tracking = true;
      EXPECT_NEAR(sample[2].get<double>(), 0.008, 1e-9);
    }
  }
  EXPECT_TRUE(tracking);
  double before = 0.0, after = 0.0;
  for (const auto& sample : parsed["tessera_texture_bytes"]["samples"]) {
    (sample[1]["stage"] == "before" ? before : after) = sample[2].get<double>();
  }
  EXPECT_EQ(before, 9000.0);
  EXPECT_EQ(after, 4500.0);
  EXPECT_EQ(parsed["tessera_compression_ratio"]["samples"][0][2], 2.0);
  fs::remove_all(dir);
}

// Ten hours at 30 frames/s: the history stays under its bound, keeps the first point, reaches
// the last minutes, and stays in time order.
TEST(MapMonitor, HistoryStaysBoundedOnALongRunAndKeepsItsShape) {
  MapMonitor monitor;
  monitor.start("long");
  const std::size_t frames = 10 * 3600 * 30;
  for (std::size_t i = 0; i < frames; i += 3) {  // every 3rd frame is enough to fill it
    MonitorFrame frame;
    frame.frames_done = i + 1;
    frame.elapsed_s = static_cast<double>(i) / 30.0;
    frame.map_bytes = i;
    monitor.onFrame(frame);
  }
  const std::vector<HistoryPoint> history = monitor.history();
  EXPECT_LE(history.size(), MapMonitor::kMaxHistory);
  EXPECT_GE(history.size(), MapMonitor::kMaxHistory / 2);
  EXPECT_EQ(history.front().elapsed_s, 0.0);
  EXPECT_GT(history.back().elapsed_s, 10 * 3600.0 - 3600.0);
  for (std::size_t i = 1; i < history.size(); ++i) {
    EXPECT_GT(history[i].elapsed_s, history[i - 1].elapsed_s);
  }
}

}  // namespace
}  // namespace tessera::pipeline
