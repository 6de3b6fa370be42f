#pragma once
// The PostgreSQL texture store, for a fleet sharing one database: the tables of
// internal/schema_sql.h, written through libpqxx with parameterised statements only. One writer
// connection behind a mutex and a pool of reader connections, as the SQLite store; several
// processes may write at once: a texture's content key is UNIQUE and each texture is inserted
// with ON CONFLICT DO NOTHING, so the same pixels are stored once whoever commits first.
// Opening, the pool and the writes are in postgres_store.cpp, the reads in
// postgres_store_reads.cpp.
//
// Credentials come from libpq's own sources (the URL without its password, PGPASSWORD,
// ~/.pgpass); location() and every message show the URL without its password. TLS is used
// when the server offers it (libpq's sslmode=prefer).
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <pqxx/pqxx>

#include "internal/connection_pool.h"
#include "internal/postgres_open.h"
#include "tessera/core/error.h"
#include "tessera/db/texture_store.h"

namespace tessera::db::internal {

struct EncodedTexture;

class PostgresStore final : public TextureStore {
 public:
  PostgresStore(const std::string& url, const OpenOptions& options);
  ~PostgresStore() override;

  std::string location() const override { return location_; }
  std::int64_t beginRun(const std::string& source) override;
  void finishRun(std::int64_t run_id) override;
  std::vector<std::int64_t> commit(const Commit& commit) override;
  std::vector<std::int64_t> removeUnused(std::int64_t run_id,
                                         const std::vector<std::int64_t>& candidates) override;

  std::optional<std::int64_t> findByContentKey(const std::string& key) const override;
  std::optional<TextureRecord> texture(std::int64_t id) const override;
  std::vector<CcvEntry> ccvVectors(std::int64_t after_id) const override;
  std::vector<TextureSummary> textures() const override;
  std::vector<TextureInstance> instances(std::optional<std::int64_t> run_id) const override;
  std::vector<RunRecord> runs() const override;
  StoreStats stats() const override;

 private:
  // A pooled connection lent for one read; none when all are out, and reset when it broke
  // (onConnection connects).
  using ReadLease = ConnectionPool<pqxx::connection>::Lease;

  std::unique_ptr<pqxx::connection> connect() const;  // throws ServerUnavailable
  // Runs `work(connection)`, connecting first when `connection` is closed. When the
  // connection breaks (the server restarted or went away) it connects once more and runs
  // `work` again, then throws ServerUnavailable. Running twice is safe: reads are reads, and
  // a commit stored twice stores nothing new.
  template <typename F>
  auto onConnection(std::unique_ptr<pqxx::connection>& connection, F&& work) const;
  // Runs `work(transaction)` in a read-only transaction on a pooled connection: one committed
  // snapshot. libpqxx's errors become core::Error naming the database.
  template <typename F>
  auto read(F&& work) const;
  void checkWritable() const;
  std::vector<std::int64_t> writeCommit(pqxx::connection& db, const Commit& commit,
                                        const std::vector<EncodedTexture>& encoded);

  std::string url_;       // as given: never printed
  std::string location_;  // redacted
  int schema_version_ = kSchemaVersion;
  std::mutex write_mutex_;
  bool read_only_ = false;
  bool may_remove_ = true;                    // false once the role was refused DELETE on textures
  std::unique_ptr<pqxx::connection> writer_;  // null until the first write, or after a break
  mutable ConnectionPool<pqxx::connection> pool_;  // idle readers
};

// True for the errors that mean the connection is gone rather than the statement wrong:
// libpqxx's broken_connection and in_doubt_error, and the server's SQLSTATE classes 08
// (connection exception) and 57P (operator intervention: shutdown, restart).
bool connectionLost(const std::exception& error);
// libpq's multi-line messages on one line.
std::string oneLine(const std::string& text);

template <typename F>
auto PostgresStore::onConnection(std::unique_ptr<pqxx::connection>& connection, F&& work) const {
  for (int attempt = 0;; ++attempt) {
    try {
      if (!connection || !connection->is_open()) connection = connect();
      return work(*connection);
    } catch (const std::exception& e) {
      if (!connectionLost(e)) throw;
      connection.reset();
      if (attempt == 1) {
        throw ServerUnavailable(
            fmt::format("{}: the server went away: {}", location_, oneLine(e.what())));
      }
    }
  }
}

template <typename F>
auto PostgresStore::read(F&& work) const {
  ReadLease lease(pool_);
  try {
    return onConnection(lease.connection(), [&](pqxx::connection& connection) {
      pqxx::read_transaction tx(connection);
      return work(tx);
    });
  } catch (const core::Error&) {
    throw;
  } catch (const std::exception& e) {
    throw core::Error(fmt::format("{}: cannot read: {}", location_, e.what()));
  }
}

}  // namespace tessera::db::internal
