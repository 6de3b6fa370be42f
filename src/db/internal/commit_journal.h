#pragma once
// The commits a server's store could not send yet, kept in a local SQLite file in the order
// they were made, until the server takes them. Each queued texture gets a provisional id
// (kProvisionalIdBase and up) that the pipeline uses like any other; once the texture is on
// the server, the journal remembers which server id it became, so later commits naming the
// provisional id are sent with the real one. The file survives the process: a run that ends
// with the server still away leaves it for `tessera db flush`.
//
// Not thread-safe: its owner (QueuedServerStore) serialises every call.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "internal/encoded_texture.h"
#include "internal/sqlite_connection.h"
#include "tessera/db/texture_store.h"

namespace tessera::db::internal {

// Far above any id a server's sequence reaches, and below 2^53 so JSON keeps it exact.
constexpr std::int64_t kProvisionalIdBase = std::int64_t{1} << 48;
inline bool isProvisional(std::int64_t id) { return id >= kProvisionalIdBase; }

struct JournalEntry {
  std::int64_t seq = 0;
  std::optional<std::int64_t> finish_run;     // a finishRun, not a commit
  Commit commit;                              // textures decoded; instance ids as queued
  std::vector<std::int64_t> provisional_ids;  // of commit.textures, in order
};

class CommitJournal {
 public:
  // Opens or creates the journal at `path` for the server at `server` (its URL without a
  // password). Throws core::Error naming the file when it is a journal of another server, not
  // a journal, or cannot be created.
  CommitJournal(const std::filesystem::path& path, const std::string& server,
                std::size_t max_bytes);

  const std::filesystem::path& path() const { return path_; }
  // The server the journal was written for, as its meta table says.
  static std::string serverOf(const std::filesystem::path& path);

  // Queues a commit (encoded as for the server); returns the provisional ids of its new
  // textures. Throws core::Error when the journal is full; nothing of the commit is queued.
  std::vector<std::int64_t> append(const Commit& commit,
                                   const std::vector<EncodedTexture>& encoded);
  void appendFinish(std::int64_t run_id);

  std::optional<JournalEntry> oldest();
  // `entry` is on the server now, its new textures under `server_ids`: it leaves the journal.
  void remove(const JournalEntry& entry, const std::vector<std::int64_t>& server_ids);

  std::optional<std::int64_t> serverId(std::int64_t provisional_id);
  std::optional<TextureRecord> texture(std::int64_t provisional_id);
  std::optional<std::int64_t> findByContentKey(const std::string& key);

  std::size_t entries();
  std::size_t bytes() const;

 private:
  std::filesystem::path path_;
  std::size_t max_bytes_;
  Connection db_;
};

}  // namespace tessera::db::internal
