#pragma once
// The texture database: SQLite (embedded, one robot) or PostgreSQL (a server a fleet shares),
// behind one narrow interface. Every method is thread-safe:
// readers (the matchers) work on committed data while the commit stage writes. Each commit is
// one transaction; a crash keeps every commit before it and nothing of the one in flight.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tessera/core/error.h"
#include "tessera/db/texture_record.h"

namespace tessera::db {

// Thrown by a server's store when the server cannot be reached now (refused, restarted, the
// network gone, a commit whose outcome is unknown). Trying the same commit again later is
// safe: a commit stored twice stores nothing new (content keys, versioned instances).
class ServerUnavailable : public core::Error {
 public:
  using core::Error::Error;
};

// The schema this build writes. A database with a higher version is refused; one of version 1
// (no instance layers) is migrated when opened for writing, and read as it is when read-only.
constexpr int kSchemaVersion = 2;

// One commit: new textures, and instances. An instance with texture_id < 0 refers to the new
// texture at index (-texture_id - 1) of `textures`. A patch may have several instances, one
// per layer (0 its texture, 1.. overlays), all of one version; a commit may carry several
// layers of a patch. A newer version of a patch replaces every stored layer of that run and
// patch (layers it no longer has are removed); an older one, arriving late, is ignored with
// all its layers; the same version replaces the stored instance of each layer it carries.
// A patch of a run that is gone from the map (merged into another after a loop closure): every
// layer of it is removed.
struct RetiredPatch {
  std::int64_t run_id = 0;
  int patch_id = 0;
};

struct Commit {
  std::vector<TextureRecord> textures;
  std::vector<TextureInstance> instances;
  std::vector<RetiredPatch> retired;  // removed before the instances are written
};

struct CcvEntry {
  std::int64_t id = 0;
  std::vector<float> ccv;
};

// How a server's store fared with its server during a run: when the server was away, commits
// waited in a local journal and were sent when it came back.
struct ServerLink {
  std::size_t outages = 0;            // times the server went away
  double disconnected_s = 0.0;        // time commits were queued instead of sent
  std::size_t queued_commits = 0;     // commits (and run ends) that waited in the journal
  std::size_t replayed_commits = 0;   // of those, sent when the server came back
  std::size_t replayed_textures = 0;  // new textures those carried
  std::size_t refused_commits = 0;    // replayed but refused by the server (logged)
  std::size_t pending_commits = 0;    // still in the journal: the server did not come back
  std::size_t removed_at_end = 0;     // unused textures removed at the run's end, not at once,
                                      // because commits were queued when they became unused
  std::string journal;                // the journal's path
};

class TextureStore {
 public:
  virtual ~TextureStore() = default;

  // Where it is (a file path, or a server URL without credentials), for messages.
  virtual std::string location() const = 0;

  virtual std::int64_t beginRun(const std::string& source) = 0;
  virtual void finishRun(std::int64_t run_id) = 0;

  // Stores `commit` in one transaction; returns the ids given to its new textures, in order.
  // Throws core::Error naming the database when it cannot (disk full, read-only); nothing of
  // that commit is then stored.
  virtual std::vector<std::int64_t> commit(const Commit& commit) = 0;

  // Removes those of `candidates` that run `run_id` stored and that no instance of any run
  // uses, in one transaction; returns the ids removed, ascending. A run calls it with the
  // textures a patch's older version used, once the newer version is committed, so that a
  // surface finalized again does not leave its superseded textures stored. Imported textures
  // and other runs' are never removed. Throws core::Error naming the database when it cannot
  // (then nothing is removed).
  virtual std::vector<std::int64_t> removeUnused(std::int64_t run_id,
                                                 const std::vector<std::int64_t>& candidates) = 0;

  // The id of a stored texture with these pixels (contentKey), if any.
  virtual std::optional<std::int64_t> findByContentKey(const std::string& key) const = 0;
  // A whole texture (pixels, features, lattice), or nothing for an unknown id.
  virtual std::optional<TextureRecord> texture(std::int64_t id) const = 0;
  // The CCVs of textures with id > after_id, ascending (to build or extend a CcvIndex).
  virtual std::vector<CcvEntry> ccvVectors(std::int64_t after_id = 0) const = 0;
  virtual std::vector<TextureSummary> textures() const = 0;
  // The instances of one run, or of every run, ordered by run, patch and layer.
  virtual std::vector<TextureInstance> instances(std::optional<std::int64_t> run_id = {}) const = 0;
  virtual std::vector<RunRecord> runs() const = 0;
  virtual StoreStats stats() const = 0;

  // A server's store hands out provisional ids for textures it had to queue; this is the id
  // the server gave such a texture once it took it (any other id is returned as it is).
  virtual std::int64_t resolvedId(std::int64_t id) const { return id; }
  // Nothing for a file's store.
  virtual std::optional<ServerLink> serverLink() const { return std::nullopt; }
};

struct OpenOptions {
  bool create = true;      // create the file (and schema) when it does not exist
  bool read_only = false;  // never write (db list, db show)
  // A server's store, writable: where commits wait while the server is away (empty: a file
  // in the temporary directory), how large that file may grow, and how long finishRun waits
  // for the server to take what waits there.
  std::filesystem::path journal{};
  std::size_t journal_max_mb = 2048;
  double finish_wait_s = 30.0;
};

// Opens the SQLite database at `path`. Throws core::Error naming the file when it is not a
// tessera database, is corrupt, was written by a newer schema, or cannot be created.
std::unique_ptr<TextureStore> openSqliteStore(const std::filesystem::path& path,
                                              const OpenOptions& options = {});

// A location from the command line: a file path opens SQLite; a postgresql:// (or postgres://)
// URL opens PostgreSQL through libpq, which also takes the password from PGPASSWORD or
// ~/.pgpass. Throws core::Error naming the location (without a password) when it cannot.
std::unique_ptr<TextureStore> openTextureStore(const std::string& location,
                                               const OpenOptions& options = {});

// A location as a file that outlives the run names it (a saved map): a file path made
// absolute, a server's URL without its password. Two locations name the same database when
// these agree.
std::string lastingLocation(const std::string& location);

// Wraps a server's store so that its commits wait in a local journal (options.journal, or a
// new file in the temporary directory) while the server is away (ServerUnavailable), and are
// sent in order when it is back. openTextureStore does this for every writable server URL.
std::unique_ptr<TextureStore> queueWhileAway(std::unique_ptr<TextureStore> server,
                                             const OpenOptions& options = {});

// Sends what a run left in `journal` (OUT/db_journal.sqlite, when its server was away at the
// end) to the server it was written for, or to `server` (the same database, its URL with a
// password), waiting up to `wait_s` for the last of it. Returns what was sent and what is left;
// an empty journal is removed. Throws core::Error naming the journal or the server when it
// cannot start (not a journal, the server unreachable).
ServerLink flushJournal(const std::filesystem::path& journal, const std::string& server = {},
                        double wait_s = 60.0);

}  // namespace tessera::db
