#pragma once
// The SQLite texture store: one writer connection behind a mutex, and a pool of read-only
// connections so that reads run (each on its WAL snapshot) while a commit is being written.
// Opening, the pool and the writes are in sqlite_store.cpp, the reads in sqlite_store_reads.cpp.
//
// Thread-safety: every method may be called from any number of threads at once. Writes are
// serialised by write_mutex_; a read borrows a connection of its own from the pool.
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "internal/connection_pool.h"
#include "internal/sqlite_connection.h"
#include "tessera/db/texture_store.h"

namespace tessera::db::internal {

struct EncodedTexture;

class SqliteStore final : public TextureStore {
 public:
  SqliteStore(const std::filesystem::path& path, const OpenOptions& options);
  ~SqliteStore() override;

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
  // A pooled read-only connection, lent for one read (opened when none is idle) and given back
  // when the lease ends.
  class ReadLease {
   public:
    explicit ReadLease(const SqliteStore& store);
    ~ReadLease();
    Connection& operator*() const { return *lease_.connection(); }

   private:
    mutable ConnectionPool<Connection>::Lease lease_;
  };

  // The writer connection; the caller holds write_mutex_. Throws for a read-only store.
  Connection& writer();
  std::vector<std::int64_t> writeCommit(const Commit& commit,
                                        const std::vector<EncodedTexture>& encoded);

  std::filesystem::path path_;
  std::string location_;
  // The schema the file had when opened: kSchemaVersion when writable (older ones are migrated),
  // possibly older when read-only (reads then fill in what the older schema lacks).
  int schema_version_ = kSchemaVersion;
  std::mutex write_mutex_;
  std::unique_ptr<Connection> writer_;  // null when read-only
  mutable ConnectionPool<Connection> pool_;  // idle readers
};

}  // namespace tessera::db::internal
