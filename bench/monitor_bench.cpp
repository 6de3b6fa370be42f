// What watching a run costs: MapMonitor's update alone (ns per frame), and a replay of the
// default recording with and without the HTTP monitor serving 50 slow event-stream clients
// (each reads a chunk, then sleeps a second) plus 5 that connect and never read.
//
//   monitor_bench [SOURCE] [--clients N] [--rounds R]
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "bench_frames.h"
#include "tessera/core/error.h"
#include "tessera/core/log.h"
#include "tessera/monitor/monitor_server.h"
#include "tessera/pipeline/map_monitor.h"
#include "tessera/pipeline/run.h"

namespace {

using Clock = std::chrono::steady_clock;
namespace pipeline = tessera::pipeline;

double updateNs() {
  pipeline::MapMonitor monitor;
  monitor.start("bench");
  constexpr int kUpdates = 1'000'000;
  const auto start = Clock::now();
  for (int i = 0; i < kUpdates; ++i) {
    pipeline::MonitorFrame frame;
    frame.frames_done = static_cast<std::size_t>(i);
    frame.elapsed_s = 1e-3 * i;
    monitor.onFrame(frame);
  }
  return std::chrono::duration<double, std::nano>(Clock::now() - start).count() / kUpdates;
}

// A client of /events that reads slowly (64 bytes a second), or never; when the server drops
// it (its write timeout), it connects again. Returns how many times it was dropped.
std::size_t slowClient(int port, const std::atomic<bool>& stop, bool never_read) {
  std::size_t dropped = 0;
  while (!stop) {
    const int sock = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(static_cast<std::uint16_t>(port));
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    int small = 1024;  // a small receive buffer: the server's writes back up sooner
    setsockopt(sock, SOL_SOCKET, SO_RCVBUF, &small, sizeof(small));
    if (connect(sock, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0) {
      const std::string request = "GET /events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";
      if (send(sock, request.data(), request.size(), 0) > 0) {
        char buffer[64];
        while (!stop) {
          if (never_read) {
            char probe;  // only notices the server closing
            if (recv(sock, &probe, 1, MSG_PEEK | MSG_DONTWAIT) == 0) break;
          } else if (recv(sock, buffer, sizeof(buffer), 0) <= 0) {
            break;
          }
          std::this_thread::sleep_for(std::chrono::seconds(1));
        }
        dropped += stop ? 0 : 1;
      }
    }
    close(sock);
  }
  return dropped;
}

double replayFps(const std::string& source_path, bool watched, int clients) {
  auto source = tessera::bench::openSource(source_path, std::nullopt, std::nullopt);
  pipeline::MapMonitor monitor;
  pipeline::RunOptions options;
  options.out_dir = "/tmp/tessera_monitor_bench";
  options.monitor = &monitor;
  std::unique_ptr<tessera::monitor::MonitorServer> server;
  std::atomic<bool> stop{false};
  std::vector<std::thread> threads;
  std::atomic<std::size_t> dropped{0};
  if (watched) {
    tessera::monitor::MonitorServerOptions server_options;
    server_options.db = (options.out_dir / "textures.db").string();
    server = std::make_unique<tessera::monitor::MonitorServer>(monitor, server_options);
    for (int i = 0; i < clients + 5; ++i) {
      threads.emplace_back([&, i, port = server->port()] {
        dropped += slowClient(port, stop, i >= clients);
      });
    }
  }
  const pipeline::RunSummary summary =
      pipeline::runPipeline(*source, pipeline::loadRunConfig(std::nullopt), options);
  stop = true;
  if (server) server->stop();
  for (std::thread& t : threads) t.join();
  if (watched) fmt::print("  clients dropped by the server's write timeout: {}\n", dropped.load());
  return summary.fps;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Cost of the map monitor: update time and replay frames/s with slow clients"};
  std::string source_path;
  int clients = 50, rounds = 2;
  app.add_option("SOURCE", source_path, "Recording to replay (default: recordings/office.oni)");
  app.add_option("--clients", clients, "Slow event-stream clients")->capture_default_str();
  app.add_option("--rounds", rounds, "Replays each way, alternating")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  tessera::core::initLogging("warn");
  try {
    if (source_path.empty()) source_path = std::string(TESSERA_SOURCE_DIR) + "/recordings/office.oni";
    fmt::print("MapMonitor::onFrame: {:.0f} ns per update\n", updateNs());
    double plain = 0.0, watched = 0.0;
    replayFps(source_path, false, clients);  // warm-up: the first replay of a process is slower
    for (int r = 0; r < rounds; ++r) {
      // Alternating which goes first: the second run of a pair finds the files cached.
      const bool watched_first = r % 2 == 1;
      const double first = replayFps(source_path, watched_first, clients);
      const double second = replayFps(source_path, !watched_first, clients);
      const double a = watched_first ? second : first;
      const double b = watched_first ? first : second;
      fmt::print("round {}: {:.2f} frames/s unwatched, {:.2f} with {} slow + 5 stuck clients\n",
                 r + 1, a, b, clients);
      plain += a;
      watched += b;
    }
    fmt::print("{}: {:.2f} against {:.2f} frames/s ({:+.1f} %)\n", source_path, watched / rounds,
               plain / rounds, 100.0 * (watched - plain) / plain);
  } catch (const tessera::core::Error& e) {
    fmt::print(stderr, "monitor_bench: {}\n", e.what());
    return 1;
  }
  return 0;
}
