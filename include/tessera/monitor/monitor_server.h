#pragma once
// The read-only HTTP view of a run (`tessera run --monitor`) or of a texture database
// (`tessera db serve`): /metrics (Prometheus), /stats (JSON), /events (server-sent events),
// /history, /textures and /textures/ID.png, and / (the page). It serves only these paths,
// never files named by a URL; it binds to 127.0.0.1 unless told otherwise, and with a token
// refuses every request without it. It reads the MapMonitor and never waits on the pipeline;
// a slow or stuck client holds one of its own threads, up to its write timeout.
#include <cstddef>
#include <memory>
#include <optional>
#include <string>

#include "tessera/pipeline/map_monitor.h"

namespace tessera::monitor {

struct ListenAddress {
  std::string host = "127.0.0.1";
  int port = 0;  // 0: any free port
};

// "PORT", "HOST:PORT" or "[IPv6]:PORT"; throws core::Error naming the text when it is not one.
ListenAddress parseListenAddress(const std::string& text);

struct MonitorServerOptions {
  ListenAddress listen;
  // When not empty, every request must carry it: "Authorization: Bearer TOKEN", or
  // "?token=TOKEN" (what a browser's page and EventSource can send).
  std::string token;
  // The texture database /textures lists (opened read-only when first asked); none: empty.
  std::optional<std::string> db;
  std::size_t max_event_streams = 64;  // more /events clients at once get 503
  int write_timeout_s = 5;             // a client that does not read is dropped after this
};

class MonitorServer {
 public:
  // Binds and starts serving on threads of its own; throws core::Error naming the address
  // when it cannot bind.
  MonitorServer(const pipeline::MapMonitor& monitor, MonitorServerOptions options);
  ~MonitorServer();
  MonitorServer(const MonitorServer&) = delete;
  MonitorServer& operator=(const MonitorServer&) = delete;

  int port() const;
  std::string url() const;  // http://HOST:PORT/
  void stop();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera::monitor
