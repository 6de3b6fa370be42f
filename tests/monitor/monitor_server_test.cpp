// The monitor's HTTP server: only its paths, only GET, the token, the event stream, the
// texture gallery from a real database; and a replay of the default recording whose /stats
// ends with report.json.
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "db/store_test_support.h"
#include "support/test_data.h"
#include "tessera/db/texture_store.h"
#include "tessera/drivers/oni/oni_source.h"
#include "tessera/monitor/monitor_server.h"
#include "tessera/pipeline/map_monitor.h"
#include "tessera/pipeline/run.h"

// Last: it brings <resolv.h>, whose _res macro breaks Eigen headers included after it.
#include <httplib.h>

namespace tessera::monitor {
namespace {

namespace fs = std::filesystem;

struct Served {
  pipeline::MapMonitor monitor;
  std::unique_ptr<MonitorServer> server;
  explicit Served(MonitorServerOptions options = {}) {
    monitor.start("test");
    server = std::make_unique<MonitorServer>(monitor, std::move(options));
  }
  httplib::Client client() const {
    httplib::Client c("127.0.0.1", server->port());
    c.set_read_timeout(5, 0);
    return c;
  }
};

TEST(MonitorServer, BindsToLoopbackUnlessToldAndParsesListenAddresses) {
  Served served;
  EXPECT_EQ(served.server->url().rfind("http://127.0.0.1:", 0), 0u) << served.server->url();
  EXPECT_EQ(parseListenAddress("9100").host, "127.0.0.1");
  EXPECT_EQ(parseListenAddress("9100").port, 9100);
  EXPECT_EQ(parseListenAddress("0.0.0.0:80").host, "0.0.0.0");
  EXPECT_EQ(parseListenAddress("[::1]:8080").host, "::1");
  EXPECT_THROW(parseListenAddress("host:port"), core::Error);
  EXPECT_THROW(parseListenAddress("99999"), core::Error);
  EXPECT_THROW(parseListenAddress("/etc/passwd"), core::Error);
}

TEST(MonitorServer, AnAddressInUseIsOneClearError) {
  Served first;
  MonitorServerOptions options;
  options.listen.port = first.server->port();
  pipeline::MapMonitor monitor;
  try {
    MonitorServer second(monitor, options);
    FAIL() << "bound twice to port " << options.listen.port;
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find(std::to_string(options.listen.port)), std::string::npos)
        << e.what();
  }
}

// Nothing but the known paths: traversal attempts, encoded or not, find nothing.
TEST(MonitorServer, ServesOnlyItsOwnPathsAndNoFile) {
  Served served;
  httplib::Client client = served.client();
  for (const char* path :
       {"/../../etc/passwd", "/textures/../../etc/passwd", "/textures/1.png/../../../etc/passwd",
        "/%2e%2e/%2e%2e/etc/passwd", "/textures/..%2F..%2Fetc%2Fpasswd.png", "/index.html",
        "/stats/../../etc/passwd", "//etc/passwd", "/textures/-1.png"}) {
    const auto res = client.Get(path);
    ASSERT_TRUE(res) << path;
    EXPECT_TRUE(res->status == 404 || res->status == 400) << path << " -> " << res->status;
    EXPECT_EQ(res->body.find("root:"), std::string::npos) << path;
  }
  for (const char* path : {"/", "/metrics", "/stats", "/history", "/textures"}) {
    const auto res = client.Get(path);
    ASSERT_TRUE(res) << path;
    EXPECT_EQ(res->status, 200) << path;
  }
}

TEST(MonitorServer, IsReadOnly) {
  Served served;
  httplib::Client client = served.client();
  for (const auto& res : {client.Post("/stats", "x", "text/plain"),
                          client.Put("/textures", "x", "text/plain"), client.Delete("/textures")}) {
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 405);
  }
}

TEST(MonitorServer, WithATokenRefusesEveryRequestWithoutIt) {
  MonitorServerOptions options;
  options.token = "s3cret-token";
  Served served(options);
  httplib::Client client = served.client();
  for (const char* path : {"/", "/metrics", "/stats", "/events", "/textures", "/nowhere"}) {
    const auto res = client.Get(path);
    ASSERT_TRUE(res) << path;
    EXPECT_EQ(res->status, 401) << path;
  }
  EXPECT_EQ(client.Get("/stats", {{"Authorization", "Bearer wrong-token!"}})->status, 401);
  EXPECT_EQ(client.Get("/stats", {{"Authorization", "Bearer s3cret-token"}})->status, 200);
  EXPECT_EQ(client.Get("/stats?token=s3cret-token")->status, 200);
  EXPECT_EQ(client.Get("/stats?token=s3cret")->status, 401);
}

// Updates reach an event-stream client as they happen, and the pipeline's side never waits.
TEST(MonitorServer, TheEventStreamCarriesEachUpdate) {
  Served served;
  std::atomic<bool> feeding{true};
  std::thread feeder([&] {
    for (std::size_t i = 1; feeding; ++i) {
      pipeline::MonitorFrame frame;
      frame.frames_done = i;
      frame.elapsed_s = 0.01 * static_cast<double>(i);
      served.monitor.onFrame(frame);
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  });
  httplib::Client client = served.client();
  std::string received;
  std::size_t events = 0;
  std::size_t last_frames = 0;
  bool increasing = true;
  client.Get("/events", [&](const char* data, std::size_t length) {
    received.append(data, length);
    for (std::size_t end; (end = received.find("\n\n")) != std::string::npos;) {
      const std::string message = received.substr(0, end);
      received.erase(0, end + 2);
      const std::size_t at = message.find("data: ");
      if (message.rfind("event: stats", 0) != 0 || at == std::string::npos) continue;
      const auto stats = nlohmann::json::parse(message.substr(at + 6));
      const auto frames = stats["frames"].get<std::size_t>();
      increasing = increasing && (events == 0 || frames > last_frames);
      last_frames = frames;
      ++events;
    }
    return events < 4;
  });
  feeding = false;
  feeder.join();
  EXPECT_EQ(events, 4u);
  EXPECT_TRUE(increasing);
  EXPECT_GT(last_frames, 0u);
}

TEST(MonitorServer, ListsTheDatabaseAndServesThumbnails) {
  const fs::path dir = fs::temp_directory_path() / "tessera_monitor_gallery";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path db_path = dir / "textures.db";
  {
    auto store = db::openSqliteStore(db_path);
    const std::int64_t run = store->beginRun("test");
    db::Commit commit;
    commit.textures = {db::test::makeTexture(1, 400, 100), db::test::makeTexture(2, 32, 24)};
    for (auto& t : commit.textures) t.run_id = run;
    for (int patch : {1, 2, 3}) {
      db::TextureInstance instance;
      instance.run_id = run;
      instance.patch_id = patch;
      instance.texture_id = patch == 3 ? -2 : -1;  // the first texture shown twice
      commit.instances.push_back(instance);
    }
    store->commit(commit);
  }
  MonitorServerOptions options;
  options.db = db_path.string();
  Served served(options);
  httplib::Client client = served.client();
  const auto list = client.Get("/textures");
  ASSERT_TRUE(list);
  ASSERT_EQ(list->status, 200);
  const auto textures = nlohmann::json::parse(list->body);
  ASSERT_EQ(textures.size(), 2u);
  EXPECT_EQ(textures[0]["uses"], 2);
  EXPECT_EQ(textures[0]["width"], 400);
  EXPECT_EQ(textures[1]["uses"], 1);
  const auto png = client.Get(textures[0]["thumbnail"].get<std::string>());
  ASSERT_TRUE(png);
  ASSERT_EQ(png->status, 200);
  EXPECT_EQ(png->get_header_value("Content-Type"), "image/png");
  const cv::Mat image = cv::imdecode(std::vector<uchar>(png->body.begin(), png->body.end()),
                                     cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(image.empty());
  EXPECT_EQ(image.cols, 192);  // shrunk to the thumbnail's longest side
  EXPECT_EQ(image.rows, 48);
  EXPECT_EQ(image.channels(), 4);  // the valid-texel mask as alpha
  EXPECT_EQ(client.Get("/textures/999.png")->status, 404);
  served.server->stop();
  fs::remove_all(dir);
}

// A replay of the default recording watched over HTTP: /stats ends with what report.json
// holds, and its live counts agree with the report's.
TEST(MonitorServer, AReplaysStatsEndWithItsReport) {
  const fs::path recording = test::sourceDir() / "recordings/office.oni";
  if (!fs::is_regular_file(recording)) {
    GTEST_SKIP() << "recordings/office.oni not rendered (configure with "
                    "TESSERA_RENDER_DEFAULT_RECORDING=ON)";
  }
  const fs::path out = fs::temp_directory_path() / "tessera_monitor_replay";
  fs::remove_all(out);
  pipeline::MapMonitor monitor;
  MonitorServerOptions options;
  options.db = (out / "textures.db").string();
  MonitorServer server(monitor, options);
  drivers::oni::OniSource source(recording);
  pipeline::RunOptions run;
  run.out_dir = out;
  run.poses = pipeline::PoseSource::kGroundTruth;
  run.max_frames = 80;
  run.monitor = &monitor;
  pipeline::runPipeline(source, pipeline::loadRunConfig(std::nullopt), run);

  httplib::Client client("127.0.0.1", server.port());
  const auto res = client.Get("/stats");
  ASSERT_TRUE(res);
  const auto stats = nlohmann::json::parse(res->body);
  nlohmann::json report;
  std::ifstream(out / "report.json") >> report;
  EXPECT_EQ(stats["state"], "finished");
  EXPECT_EQ(stats["report"], report);
  // (Patches finalized at the end of the stream come after the last frame's figures.)
  for (const char* key : {"frames", "frames_dropped", "frames_without_pose", "frames_held_apart",
                          "textures_stored", "patterns_stored"}) {
    EXPECT_EQ(stats[key], report[key]) << key;
  }
  EXPECT_GT(stats["textures_stored"].get<int>(), 0);
  // The gallery lists what the run stored and kept.
  const auto textures = nlohmann::json::parse(client.Get("/textures")->body);
  EXPECT_EQ(textures.size(), report["textures_stored"].get<std::size_t>() -
                                 report["textures_removed"].get<std::size_t>());
  server.stop();
  fs::remove_all(out);
}

}  // namespace
}  // namespace tessera::monitor
