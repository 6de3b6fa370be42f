#pragma once
// A throwaway PostgreSQL server for tests: initdb and pg_ctl (Debian's postgresql package) in a
// temporary folder, listening on 127.0.0.1 at a free port, stopped and removed afterwards.
// When the server binaries are missing, start() says why, and the test skips with that.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <pwd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

namespace tessera::test {

class PostgresCluster {
 public:
  // A running server with an empty database `tessera` owned by the superuser `tessera`, or
  // nothing, with `why_not` set. Over TCP (as the stores connect) the server asks for the
  // password (scram-sha-256): password(), which the tests hand over through PGPASSWORD. The
  // helpers below use the local socket, which trusts.
  static std::unique_ptr<PostgresCluster> start(std::string& why_not) {
    namespace fs = std::filesystem;
    fs::path bin;
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator("/usr/lib/postgresql", ec)) {
      if (fs::exists(entry.path() / "bin/initdb") && entry.path() / "bin" > bin) {
        bin = entry.path() / "bin";
      }
    }
    if (bin.empty()) {
      why_not = "no PostgreSQL server binaries (apt-get install postgresql): the PostgreSQL "
                "store's tests need a throwaway server";
      return nullptr;
    }
    auto cluster = std::unique_ptr<PostgresCluster>(new PostgresCluster());
    cluster->bin_ = bin;
    char folder[] = "/tmp/tessera_pg_XXXXXX";
    if (mkdtemp(folder) == nullptr) {
      why_not = "cannot make a temporary folder for the server";
      return nullptr;
    }
    cluster->dir_ = folder;
    // initdb refuses to run as root: the server then runs as the package's `postgres` user.
    if (geteuid() == 0) {
      if (getpwnam("postgres") == nullptr) {
        why_not = "running as root without a `postgres` user to run the server as";
        return nullptr;
      }
      cluster->as_user_ = "runuser -u postgres -- ";
      if (std::system(("chown postgres " + cluster->dir_.string()).c_str()) != 0) {
        why_not = "cannot hand the server's folder to the postgres user";
        return nullptr;
      }
    }
    cluster->port_ = freePort();
    { std::ofstream(cluster->dir_ / "password") << kPassword << '\n'; }
    if (!cluster->run("initdb -D " + cluster->data() + " -U tessera --auth-local=trust "
                      "--auth-host=scram-sha-256 --pwfile=" + cluster->dir_.string() +
                      "/password -E UTF8 --no-sync > " + cluster->dir_.string() +
                      "/initdb.log 2>&1")) {
      why_not = "initdb failed (see " + cluster->dir_.string() + "/initdb.log)";
      cluster->dir_.clear();  // kept for the log
      return nullptr;
    }
    if (!cluster->startServer()) {
      why_not = "the server did not start (see " + cluster->dir_.string() + "/server.log)";
      return nullptr;
    }
    if (!cluster->createDatabase("tessera")) {
      why_not = "createdb failed";
      return nullptr;
    }
    return cluster;
  }

  ~PostgresCluster() {
    if (running_) stopServer();
    if (!dir_.empty()) {
      std::error_code ec;
      std::filesystem::remove_all(dir_, ec);
    }
  }

  int port() const { return port_; }
  static constexpr const char* kPassword = "pg-test-Zq81x";
  static const char* password() { return kPassword; }
  std::string url(const std::string& database = "tessera") const {
    return "postgresql://tessera@127.0.0.1:" + std::to_string(port_) + "/" + database;
  }
  // Runs SQL through psql against `database`; true when psql succeeded.
  bool psql(const std::string& sql, const std::string& database = "tessera",
            const std::string& user = "tessera") const {
    const std::string file = dir_.string() + "/statement.sql";
    { std::ofstream(file) << sql << '\n'; }
    return run("psql -q -v ON_ERROR_STOP=1 -h " + dir_.string() + " -p " + std::to_string(port_) +
               " -U " + user + " -d " + database + " -f " + file + " > /dev/null 2>&1");
  }
  bool createDatabase(const std::string& name) const {
    return run("createdb -h " + dir_.string() + " -p " + std::to_string(port_) + " -U tessera " +
               name);
  }
  bool stopServer() {
    running_ = !run("pg_ctl -D " + data() + " -m fast -w stop > /dev/null 2>&1");
    return !running_;
  }
  bool startServer() {
    running_ = run("pg_ctl -D " + data() + " -w -l " + dir_.string() + "/server.log -o \"-p " +
                   std::to_string(port_) + " -k " + dir_.string() +
                   " -c listen_addresses=127.0.0.1 -c fsync=off\" start > /dev/null 2>&1");
    return running_;
  }

 private:
  PostgresCluster() = default;

  std::string data() const { return dir_.string() + "/data"; }
  bool run(const std::string& command) const {
    const std::string full = as_user_ + bin_.string() + "/" + command;
    return std::system(full.c_str()) == 0;
  }
  static int freePort() {
    const int sock = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t length = sizeof(address);
    bind(sock, reinterpret_cast<sockaddr*>(&address), sizeof(address));
    getsockname(sock, reinterpret_cast<sockaddr*>(&address), &length);
    const int port = ntohs(address.sin_port);
    close(sock);
    return port;
  }

  std::filesystem::path bin_, dir_;
  std::string as_user_;
  int port_ = 0;
  bool running_ = false;
};

}  // namespace tessera::test
