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

#include "tessera/db/texture_store.h"

namespace pqxx {
class connection;
}

namespace tessera::db::internal {

struct EncodedTexture;

// `url` without a password: postgresql://user:secret@host/db -> postgresql://user@host/db, and
// a password=... parameter dropped.
std::string redactedUrl(const std::string& url);

class PostgresStore final : public TextureStore {
 public:
  PostgresStore(const std::string& url, const OpenOptions& options);
  ~PostgresStore() override;

  std::string location() const override { return location_; }
  std::int64_t beginRun(const std::string& source) override;
  void finishRun(std::int64_t run_id) override;
  std::vector<std::int64_t> commit(const Commit& commit) override;

  std::optional<std::int64_t> findByContentKey(const std::string& key) const override;
  std::optional<TextureRecord> texture(std::int64_t id) const override;
  std::vector<CcvEntry> ccvVectors(std::int64_t after_id) const override;
  std::vector<TextureSummary> textures() const override;
  std::vector<TextureInstance> instances(std::optional<std::int64_t> run_id) const override;
  std::vector<RunRecord> runs() const override;
  StoreStats stats() const override;

 private:
  // A pooled connection lent for one read.
  class ReadLease {
   public:
    explicit ReadLease(const PostgresStore& store);
    ~ReadLease();
    ReadLease(const ReadLease&) = delete;
    ReadLease& operator=(const ReadLease&) = delete;
    pqxx::connection& operator*() const { return *connection_; }

   private:
    const PostgresStore& store_;
    std::unique_ptr<pqxx::connection> connection_;
  };

  std::unique_ptr<pqxx::connection> connect() const;
  pqxx::connection& writer();  // the caller holds write_mutex_
  std::vector<std::int64_t> writeCommit(pqxx::connection& db, const Commit& commit,
                                        const std::vector<EncodedTexture>& encoded);

  std::string url_;       // as given: never printed
  std::string location_;  // redacted
  int schema_version_ = kSchemaVersion;
  std::mutex write_mutex_;
  std::unique_ptr<pqxx::connection> writer_;  // null when read-only
  mutable std::mutex pool_mutex_;
  mutable std::vector<std::unique_ptr<pqxx::connection>> pool_;
};

}  // namespace tessera::db::internal
