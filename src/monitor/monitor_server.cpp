// The monitor's HTTP server. cpp-httplib's header is large: it is included here only.
#include "tessera/monitor/monitor_server.h"

#include <atomic>
#include <chrono>
#include <map>
#include <mutex>
#include <thread>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "internal/page.h"
#include "tessera/core/error.h"
#include "tessera/db/texture_store.h"
#include "tessera/db/texture_summary_json.h"
#include "tessera/texture/bitmap_export.h"

// Last: it brings <resolv.h>, whose _res macro breaks Eigen headers included after it.
#include <httplib.h>

namespace tessera::monitor {

namespace {

constexpr int kThumbnailPx = 192;            // longest side of a gallery thumbnail
constexpr std::size_t kThumbnailCache = 512;  // thumbnails kept encoded
constexpr auto kEventPeriod = std::chrono::milliseconds(250);  // at most 4 events/s a client
constexpr auto kKeepAlive = std::chrono::seconds(10);         // a comment line when idle

// Compares without stopping at the first difference, so timing tells nothing of the token.
bool sameToken(const std::string& a, const std::string& b) {
  unsigned char difference = a.size() == b.size() ? 0 : 1;
  for (std::size_t i = 0; i < a.size(); ++i) {
    difference |= static_cast<unsigned char>(a[i] ^ (i < b.size() ? b[i] : 0));
  }
  return difference == 0;
}

}  // namespace

ListenAddress parseListenAddress(const std::string& text) {
  const auto bad = [&](const std::string& why) {
    return core::Error(fmt::format("--monitor {}: expected PORT or ADDRESS:PORT ({})", text, why));
  };
  ListenAddress address;
  std::string port = text;
  if (!text.empty() && text.front() == '[') {  // [IPv6]:PORT
    const std::size_t close = text.find("]:");
    if (close == std::string::npos) throw bad("an IPv6 address needs [ADDRESS]:PORT");
    address.host = text.substr(1, close - 1);
    port = text.substr(close + 2);
    const bool ipv6 = !address.host.empty() &&
                      address.host.find_first_not_of("0123456789abcdefABCDEF:.") ==
                          std::string::npos;
    if (!ipv6) throw bad("not an IPv6 address");
  } else if (const std::size_t colon = text.rfind(':'); colon != std::string::npos) {
    address.host = text.substr(0, colon);
    port = text.substr(colon + 1);
    const bool name = !address.host.empty() &&
                      address.host.find_first_not_of(
                          "0123456789abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ.-") ==
                          std::string::npos;
    if (!name) throw bad("not a host name or address");
  }
  if (port.empty() || port.size() > 5 || port.find_first_not_of("0123456789") != std::string::npos) {
    throw bad("the port is not a number");
  }
  address.port = std::stoi(port);
  if (address.port > 65535) {
    throw core::Error(fmt::format("--monitor {}: port {} is out of range", text, address.port));
  }
  return address;
}

struct MonitorServer::Impl {
  const pipeline::MapMonitor& monitor;
  MonitorServerOptions options;
  httplib::Server server;
  std::thread thread;
  int port = 0;
  std::atomic<bool> stopping{false};
  std::atomic<std::size_t> event_streams{0};
  std::mutex db_mutex;
  std::unique_ptr<db::TextureStore> store;  // opened read-only when first asked
  std::map<std::int64_t, std::string> thumbnails;

  Impl(const pipeline::MapMonitor& m, MonitorServerOptions o) : monitor(m), options(std::move(o)) {}

  bool authorised(const httplib::Request& req) const {
    if (options.token.empty()) return true;
    const std::string header = req.get_header_value("Authorization");
    if (header.rfind("Bearer ", 0) == 0 && sameToken(header.substr(7), options.token)) return true;
    return req.has_param("token") && sameToken(req.get_param_value("token"), options.token);
  }

  db::TextureStore* textureStore() {  // under db_mutex
    if (!store && options.db) {
      db::OpenOptions open;
      open.create = false;
      open.read_only = true;
      store = db::openTextureStore(*options.db, open);
    }
    return store.get();
  }

  void routes();
  void serveTextures(httplib::Response& res);
  void serveThumbnail(std::int64_t id, httplib::Response& res);
  void serveEvents(httplib::Response& res);
};

void MonitorServer::Impl::routes() {
  server.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
    if (authorised(req)) return httplib::Server::HandlerResponse::Unhandled;
    res.status = 401;
    res.set_header("WWW-Authenticate", "Bearer");
    res.set_content("a token is required: Authorization: Bearer TOKEN, or ?token=TOKEN\n",
                    "text/plain");
    return httplib::Server::HandlerResponse::Handled;
  });
  server.Get("/", [](const httplib::Request&, httplib::Response& res) {
    res.set_content(std::string(kPage), "text/html; charset=utf-8");
  });
  server.Get("/metrics", [this](const httplib::Request&, httplib::Response& res) {
    res.set_content(pipeline::toPrometheus(monitor.snapshot()), "text/plain; version=0.0.4");
  });
  server.Get("/stats", [this](const httplib::Request&, httplib::Response& res) {
    res.set_content(pipeline::toJson(monitor.snapshot()).dump(), "application/json");
  });
  server.Get("/history", [this](const httplib::Request&, httplib::Response& res) {
    res.set_content(pipeline::toJson(monitor.history()).dump(), "application/json");
  });
  server.Get("/events", [this](const httplib::Request&, httplib::Response& res) {
    serveEvents(res);
  });
  server.Get("/textures", [this](const httplib::Request&, httplib::Response& res) {
    serveTextures(res);
  });
  server.Get(R"(/textures/([0-9]{1,18})\.png)",
             [this](const httplib::Request& req, httplib::Response& res) {
               serveThumbnail(std::stoll(req.matches[1].str()), res);
             });
  // Read-only: every other method is refused, whatever the path.
  const auto refuse = [](const httplib::Request&, httplib::Response& res) {
    res.status = 405;
    res.set_header("Allow", "GET, HEAD");
    res.set_content("read-only: only GET and HEAD\n", "text/plain");
  };
  server.Post(".*", refuse);
  server.Put(".*", refuse);
  server.Patch(".*", refuse);
  server.Delete(".*", refuse);
  server.Options(".*", refuse);
  server.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
    if (res.body.empty()) {
      res.set_content(res.status == 404 ? "not found: the monitor serves /, /metrics, /stats, "
                                          "/events, /history, /textures and /textures/ID.png\n"
                                        : fmt::format("error {}\n", res.status),
                      "text/plain");
    }
    spdlog::debug("monitor: {} {} -> {}", req.method, req.path, res.status);
  });
}

void MonitorServer::Impl::serveTextures(httplib::Response& res) {
  nlohmann::json list = nlohmann::json::array();
  try {
    std::lock_guard lock(db_mutex);
    if (db::TextureStore* db = textureStore()) {
      for (const db::TextureSummary& t : db->textures()) {
        nlohmann::json entry = db::summaryJson(t);
        entry["thumbnail"] = fmt::format("/textures/{}.png", t.id);
        list.push_back(std::move(entry));
      }
    }
  } catch (const std::exception& e) {
    res.status = 503;
    res.set_content(fmt::format("the texture database cannot be read: {}\n", e.what()),
                    "text/plain");
    return;
  }
  res.set_content(list.dump(), "application/json");
}

void MonitorServer::Impl::serveThumbnail(std::int64_t id, httplib::Response& res) {
  std::string png;
  try {
    std::lock_guard lock(db_mutex);
    if (const auto cached = thumbnails.find(id); cached != thumbnails.end()) {
      png = cached->second;
    } else if (db::TextureStore* db = textureStore()) {
      const std::optional<db::TextureRecord> texture = db->texture(id);
      if (texture && !texture->rgb.empty()) {
        // Stored RGB with its mask as alpha, as the map's PNGs; shrunk to thumbnail size.
        cv::Mat bgra = texture::bgraImage(texture->rgb, texture->mask);
        const double scale =
            std::min(1.0, static_cast<double>(kThumbnailPx) / std::max(bgra.cols, bgra.rows));
        if (scale < 1.0) cv::resize(bgra, bgra, {}, scale, scale, cv::INTER_AREA);
        std::vector<uchar> bytes;
        cv::imencode(".png", bgra, bytes);
        png.assign(bytes.begin(), bytes.end());
        if (thumbnails.size() >= kThumbnailCache) thumbnails.erase(thumbnails.begin());
        thumbnails[id] = png;
      }
    }
  } catch (const std::exception& e) {
    res.status = 503;
    res.set_content(fmt::format("the texture database cannot be read: {}\n", e.what()),
                    "text/plain");
    return;
  }
  if (png.empty()) {
    res.status = 404;
    res.set_content(fmt::format("no texture {}\n", id), "text/plain");
    return;
  }
  res.set_header("Cache-Control", "max-age=3600");  // a stored texture never changes
  res.set_content(png, "image/png");
}

void MonitorServer::Impl::serveEvents(httplib::Response& res) {
  if (event_streams.fetch_add(1) >= options.max_event_streams) {
    event_streams.fetch_sub(1);
    res.status = 503;
    res.set_header("Retry-After", "10");
    res.set_content("too many event streams open\n", "text/plain");
    return;
  }
  res.set_header("Cache-Control", "no-cache");
  // The generation last sent (none yet: the first call sends the current state at once).
  auto last = std::make_shared<std::optional<std::uint64_t>>();
  auto last_sent = std::make_shared<std::chrono::steady_clock::time_point>();
  res.set_chunked_content_provider(
      "text/event-stream",
      [this, last, last_sent](std::size_t, httplib::DataSink& sink) {
        if (stopping) {
          sink.done();
          return true;
        }
        // Waiting is on the monitor's condition, never on the pipeline's locks.
        const std::uint64_t now =
            *last ? monitor.waitPast(**last, std::chrono::milliseconds(1000))
                  : monitor.waitPast(0, std::chrono::milliseconds(0));
        std::string message;
        if (!*last || now > **last) {
          *last = now;
          message = "event: stats\ndata: " + pipeline::toJson(monitor.snapshot()).dump() + "\n\n";
        } else if (std::chrono::steady_clock::now() - *last_sent > kKeepAlive) {
          message = ": idle\n\n";
        }
        if (!message.empty()) {
          if (!sink.write(message.data(), message.size())) return false;
          *last_sent = std::chrono::steady_clock::now();
          std::this_thread::sleep_for(kEventPeriod);
        }
        return true;
      },
      [this](bool) { event_streams.fetch_sub(1); });
}

MonitorServer::MonitorServer(const pipeline::MapMonitor& monitor, MonitorServerOptions options)
    : impl_(std::make_unique<Impl>(monitor, std::move(options))) {
  Impl& s = *impl_;
  const std::size_t threads = s.options.max_event_streams + 8;
  s.server.new_task_queue = [threads] { return new httplib::ThreadPool(threads); };
  s.server.set_read_timeout(5, 0);
  s.server.set_write_timeout(s.options.write_timeout_s, 0);
  s.server.set_keep_alive_timeout(5);
  s.server.set_payload_max_length(64 * 1024);  // read-only: requests carry no body
  // SO_REUSEADDR only: httplib's default adds SO_REUSEPORT, which would let a second run bind
  // the same port and take half of the first one's requests.
  s.server.set_socket_options([](socket_t sock) {
    const int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
  });
  s.routes();
  const ListenAddress& at = s.options.listen;
  s.port = at.port == 0 ? s.server.bind_to_any_port(at.host)
                        : (s.server.bind_to_port(at.host, at.port) ? at.port : -1);
  if (s.port <= 0) {
    throw core::Error(fmt::format("monitor: cannot listen on {}:{} (in use, or not an address "
                                  "of this machine)",
                                  at.host, at.port));
  }
  s.thread = std::thread([&s] { s.server.listen_after_bind(); });
  // httplib's stop() does nothing before its loop runs: wait for it, so that stopping a server
  // just made cannot leave its thread listening for ever.
  while (!s.server.is_running()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

MonitorServer::~MonitorServer() { stop(); }

int MonitorServer::port() const { return impl_->port; }

std::string MonitorServer::url() const {
  const std::string& host = impl_->options.listen.host;
  return fmt::format("http://{}:{}/",
                     host.find(':') != std::string::npos ? "[" + host + "]" : host, impl_->port);
}

void MonitorServer::stop() {
  if (!impl_->thread.joinable()) return;
  impl_->stopping = true;
  impl_->server.stop();
  impl_->thread.join();
}

}  // namespace tessera::monitor
