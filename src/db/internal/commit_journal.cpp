#include "internal/commit_journal.h"

#include <map>
#include <system_error>

#include <fmt/format.h>

#include "internal/file_bytes.h"
#include "internal/schema_sql.h"
#include "internal/sqlite_texture_rows.h"
#include "tessera/core/error.h"

namespace tessera::db::internal {

namespace {

constexpr const char* kApplication = "tessera-journal";
constexpr const char* kFormat = "1";

// The textures table is the texture database's own (schema_sql.h), its rowid + the base being
// the provisional id. Instances keep absolute texture ids: provisional or the server's.
constexpr const char* kJournalTables = R"sql(
CREATE TABLE entries (
  seq INTEGER PRIMARY KEY,
  finish_run INTEGER,
  queued_utc TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%SZ', 'now'))
);
CREATE TABLE entry_textures (
  seq INTEGER NOT NULL,
  idx INTEGER NOT NULL,
  texture_id INTEGER NOT NULL,
  PRIMARY KEY (seq, idx)
);
CREATE TABLE entry_instances (
  seq INTEGER NOT NULL,
  run_id INTEGER NOT NULL, patch_id INTEGER NOT NULL, version INTEGER NOT NULL,
  layer INTEGER NOT NULL, texture_id INTEGER NOT NULL,
  a REAL NOT NULL, b REAL NOT NULL, tx REAL NOT NULL, ty REAL NOT NULL,
  psnr_db REAL, reused INTEGER NOT NULL
);
CREATE TABLE entry_retired (seq INTEGER NOT NULL, run_id INTEGER NOT NULL,
                            patch_id INTEGER NOT NULL);
CREATE TABLE resolved (provisional_id INTEGER PRIMARY KEY, server_id INTEGER NOT NULL);
)sql";

std::string metaValue(Connection& db, const char* key) {
  Statement query(db, "SELECT value FROM meta WHERE key = ?");
  query.bind(1, std::string(key));
  return query.step() ? query.text(0) : std::string();
}

bool hasMeta(Connection& db) {
  Statement query(db, "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'meta'");
  return query.step();
}

// One write transaction; rolled back when `write` throws.
template <typename F>
auto inTransaction(Connection& db, F&& write) {
  db.exec("BEGIN IMMEDIATE");
  try {
    auto result = write();
    db.exec("COMMIT");
    return result;
  } catch (...) {
    db.rollbackQuietly();
    throw;
  }
}

}  // namespace

CommitJournal::CommitJournal(const std::filesystem::path& path, const std::string& server,
                             std::size_t max_bytes)
    : path_(path),
      max_bytes_(max_bytes),
      db_(path, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE) {
  sqlite3_busy_timeout(db_.handle(), 5000);
  // Each queued commit is synced: the server's copy is what it stands in for.
  db_.exec("PRAGMA synchronous = FULL");
  if (!hasMeta(db_)) {
    inTransaction(db_, [&] {
      db_.exec(coreTablesSql(SqlDialect::kSqlite).c_str());
      db_.exec(kJournalTables);
      Statement meta(db_, "INSERT INTO meta (key, value) VALUES (?, ?)");
      for (const auto& [key, value] : std::map<std::string, std::string>{
               {"application", kApplication}, {"format", kFormat}, {"server", server}}) {
        meta.reset();
        meta.bind(1, key).bind(2, value).run();
      }
      return 0;
    });
    return;
  }
  if (metaValue(db_, "application") != kApplication) {
    throw core::Error(path_.string() + ": not a tessera commit journal");
  }
  if (metaValue(db_, "format") != kFormat) {
    throw core::Error(fmt::format("{}: a commit journal of format {} (this build reads {})",
                                  path_.string(), metaValue(db_, "format"), kFormat));
  }
  const std::string written_for = metaValue(db_, "server");
  if (written_for != server) {
    throw core::Error(fmt::format("{}: holds commits for {}, not for {}", path_.string(),
                                  written_for, server));
  }
}

std::string CommitJournal::serverOf(const std::filesystem::path& path) {
  if (!std::filesystem::exists(path)) throw core::Error(path.string() + ": no such file");
  Connection db(path, SQLITE_OPEN_READONLY);
  if (!hasMeta(db) || metaValue(db, "application") != kApplication) {
    throw core::Error(path.string() + ": not a tessera commit journal");
  }
  return metaValue(db, "server");
}

std::vector<std::int64_t> CommitJournal::append(const Commit& commit,
                                                const std::vector<EncodedTexture>& encoded) {
  if (bytes() > max_bytes_) {
    throw core::Error(fmt::format("{}: the commit journal is full ({} MB); the commit is not kept",
                                  path_.string(), max_bytes_ >> 20));
  }
  return inTransaction(db_, [&] {
    Statement entry(db_, "INSERT INTO entries (finish_run) VALUES (NULL)");
    entry.run();
    const std::int64_t seq = db_.lastInsertId();
    std::vector<std::int64_t> ids;
    Statement insert(db_, kInsertTexture);
    Statement own(db_, "INSERT INTO entry_textures (seq, idx, texture_id) VALUES (?, ?, ?)");
    for (const EncodedTexture& texture : encoded) {
      // The same pixels already queued keep their provisional id and are sent once.
      if (const auto queued = findByContentKey(texture.content_key)) {
        ids.push_back(*queued);
        continue;
      }
      const std::int64_t row = insertTexture(insert, db_, texture);
      own.reset();
      own.bind(1, seq).bind(2, std::int64_t(ids.size())).bind(3, row).run();
      ids.push_back(kProvisionalIdBase + row);
    }
    Statement instance(db_,
                       "INSERT INTO entry_instances (seq, run_id, patch_id, version, layer, "
                       "texture_id, a, b, tx, ty, psnr_db, reused) VALUES (?, ?, ?, ?, ?, ?, ?, "
                       "?, ?, ?, ?, ?)");
    for (const TextureInstance& i : commit.instances) {
      const std::int64_t texture_id = instanceTextureId(i, ids, path_.string());
      instance.reset();
      instance.bind(1, seq).bind(2, i.run_id).bind(3, std::int64_t{i.patch_id});
      instance.bind(4, std::int64_t{i.version}).bind(5, std::int64_t{i.layer}).bind(6, texture_id);
      instance.bind(7, i.transform.a).bind(8, i.transform.b);
      instance.bind(9, i.transform.tx).bind(10, i.transform.ty);
      if (i.psnr_db) instance.bind(11, *i.psnr_db);
      instance.bind(12, std::int64_t{i.reused ? 1 : 0}).run();
    }
    Statement retired(db_, "INSERT INTO entry_retired (seq, run_id, patch_id) VALUES (?, ?, ?)");
    for (const RetiredPatch& gone : commit.retired) {
      retired.reset();
      retired.bind(1, seq).bind(2, gone.run_id).bind(3, std::int64_t{gone.patch_id}).run();
    }
    return ids;
  });
}

void CommitJournal::appendFinish(std::int64_t run_id) {
  Statement entry(db_, "INSERT INTO entries (finish_run) VALUES (?)");
  entry.bind(1, run_id).run();
}

std::optional<JournalEntry> CommitJournal::oldest() {
  Statement head(db_, "SELECT seq, finish_run FROM entries ORDER BY seq LIMIT 1");
  if (!head.step()) return std::nullopt;
  JournalEntry entry;
  entry.seq = head.int64(0);
  if (!head.isNull(1)) {
    entry.finish_run = head.int64(1);
    return entry;
  }
  // Its own new textures, decoded to be sent as any commit's.
  Statement own(db_, "SELECT texture_id FROM entry_textures WHERE seq = ? ORDER BY idx");
  own.bind(1, entry.seq);
  std::map<std::int64_t, std::int64_t> index_of;  // provisional id -> -(index + 1)
  while (own.step()) {
    const std::int64_t row = own.int64(0);
    Statement select(db_, kSelectTexture);
    select.bind(1, row);
    if (!select.step()) {
      throw core::Error(fmt::format("{}: queued texture {} is missing", path_.string(), row));
    }
    entry.commit.textures.push_back(recordOf(select, 0));
    entry.provisional_ids.push_back(kProvisionalIdBase + row);
    index_of[kProvisionalIdBase + row] = -static_cast<std::int64_t>(index_of.size()) - 1;
  }
  Statement instances(db_,
                      "SELECT run_id, patch_id, version, layer, texture_id, a, b, tx, ty, "
                      "psnr_db, reused FROM entry_instances WHERE seq = ? ORDER BY rowid");
  instances.bind(1, entry.seq);
  while (instances.step()) {
    TextureInstance& i = entry.commit.instances.emplace_back();
    i.run_id = instances.int64(0);
    i.patch_id = static_cast<int>(instances.int64(1));
    i.version = static_cast<int>(instances.int64(2));
    i.layer = static_cast<int>(instances.int64(3));
    i.texture_id = instances.int64(4);
    i.transform = {instances.real(5), instances.real(6), instances.real(7), instances.real(8)};
    if (!instances.isNull(9)) i.psnr_db = instances.real(9);
    i.reused = instances.int64(10) != 0;
    if (!isProvisional(i.texture_id)) continue;
    if (const auto it = index_of.find(i.texture_id); it != index_of.end()) {
      i.texture_id = it->second;
    } else if (const auto sent = serverId(i.texture_id)) {
      i.texture_id = *sent;
    } else {
      throw core::Error(fmt::format("{}: entry {} names texture {}, neither queued with it nor "
                                    "sent before it",
                                    path_.string(), entry.seq, i.texture_id));
    }
  }
  Statement retired(db_, "SELECT run_id, patch_id FROM entry_retired WHERE seq = ?");
  retired.bind(1, entry.seq);
  while (retired.step()) {
    entry.commit.retired.push_back({retired.int64(0), static_cast<int>(retired.int64(1))});
  }
  return entry;
}

void CommitJournal::remove(const JournalEntry& entry, const std::vector<std::int64_t>& server_ids) {
  inTransaction(db_, [&] {
    Statement resolve(db_,
                      "INSERT OR REPLACE INTO resolved (provisional_id, server_id) VALUES (?, ?)");
    Statement drop(db_, "DELETE FROM textures WHERE id = ?");
    for (std::size_t i = 0; i < entry.provisional_ids.size() && i < server_ids.size(); ++i) {
      resolve.reset();
      resolve.bind(1, entry.provisional_ids[i]).bind(2, server_ids[i]).run();
      drop.reset();
      drop.bind(1, entry.provisional_ids[i] - kProvisionalIdBase).run();
    }
    for (const char* table : {"entry_textures", "entry_instances", "entry_retired", "entries"}) {
      Statement gone(db_, fmt::format("DELETE FROM {} WHERE seq = ?", table).c_str());
      gone.bind(1, entry.seq).run();
    }
    return 0;
  });
}

std::optional<std::int64_t> CommitJournal::serverId(std::int64_t provisional_id) {
  Statement query(db_, "SELECT server_id FROM resolved WHERE provisional_id = ?");
  query.bind(1, provisional_id);
  if (!query.step()) return std::nullopt;
  return query.int64(0);
}

std::optional<TextureRecord> CommitJournal::texture(std::int64_t provisional_id) {
  Statement select(db_, kSelectTexture);
  select.bind(1, provisional_id - kProvisionalIdBase);
  if (!select.step()) return std::nullopt;
  return recordOf(select, provisional_id);
}

std::optional<std::int64_t> CommitJournal::findByContentKey(const std::string& key) {
  Statement query(db_, "SELECT id FROM textures WHERE content_key = ?");
  query.bind(1, key);
  if (!query.step()) return std::nullopt;
  return kProvisionalIdBase + query.int64(0);
}

std::size_t CommitJournal::entries() {
  Statement count(db_, "SELECT count(*) FROM entries");
  count.step();
  return static_cast<std::size_t>(count.int64(0));
}

std::size_t CommitJournal::bytes() const { return fileBytes(path_); }

}  // namespace tessera::db::internal
