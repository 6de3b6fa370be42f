#pragma once
// A server's store that keeps working while the server is away: a commit the server cannot
// take (ServerUnavailable) goes to a local CommitJournal, with provisional ids for its new
// textures, and every later commit queues behind it so the server receives them in order. A
// sender thread retries the oldest with backoff (0.25 s doubling to 5 s) and empties the
// journal when the server is back. Reads of queued textures are answered from the journal.
#include <chrono>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <thread>

#include "internal/commit_journal.h"
#include "tessera/db/texture_store.h"

namespace tessera::db::internal {

class QueuedServerStore final : public TextureStore {
 public:
  // Opens (or takes over) the journal at `journal`; commits an earlier process left there
  // are sent first.
  QueuedServerStore(std::unique_ptr<TextureStore> server, const std::filesystem::path& journal,
                    const OpenOptions& options);
  // Stops the sender. An empty journal is removed; one with commits stays, and says so.
  ~QueuedServerStore() override;

  std::string location() const override { return server_->location(); }
  std::int64_t beginRun(const std::string& source) override;
  // Waits up to OpenOptions::finish_wait_s for the journal to empty; when the server is still
  // away, the run's end is queued too and the journal named in a warning.
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
  std::int64_t resolvedId(std::int64_t id) const override;
  std::optional<ServerLink> serverLink() const override;

 private:
  void sendLoop();
  void noteOutage(const std::string& why);  // the caller holds mutex_
  void noteBack();                          // the caller holds mutex_
  Commit withServerIds(const Commit& commit) const;  // the caller holds mutex_
  // Removes those of `candidates` the server has and no instance uses; returns the caller's
  // ids of those removed. The caller holds mutex_ and has an empty journal.
  std::vector<std::int64_t> removeOnServer(std::int64_t run_id,
                                           const std::vector<std::int64_t>& candidates);

  std::unique_ptr<TextureStore> server_;
  std::unique_ptr<CommitJournal> journal_;
  std::chrono::duration<double> finish_wait_;
  mutable std::mutex mutex_;  // journal_, link_, down_
  std::condition_variable wake_;     // a commit queued, or stopping
  std::condition_variable emptied_;  // the journal became empty
  bool stopping_ = false;
  bool down_ = false;
  std::chrono::steady_clock::time_point down_since_;
  ServerLink link_;
  // Per run, removal candidates that came while commits were queued: tried at the run's end.
  std::map<std::int64_t, std::vector<std::int64_t>> deferred_removals_;
  std::thread sender_;
};

}  // namespace tessera::db::internal
