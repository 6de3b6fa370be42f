#pragma once
// RAII wrappers over the SQLite C API for the db module (the only code that includes
// sqlite3.h). Every failure becomes a core::Error that starts with the database's path, so a
// message always says which file it is about.
//
// Thread-safety: none of its own. A Connection (and its Statements) is used by one thread at a
// time; SqliteStore hands connections out under its own mutexes, which is why connections are
// opened with SQLITE_OPEN_NOMUTEX.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include <sqlite3.h>

namespace tessera::db::internal {

class Connection {
 public:
  // `flags`: SQLITE_OPEN_READONLY or SQLITE_OPEN_READWRITE [| SQLITE_OPEN_CREATE].
  Connection(const std::filesystem::path& path, int flags);
  ~Connection();
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  sqlite3* handle() const { return db_; }
  const std::string& path() const { return path_; }

  // Runs statements that return no rows (DDL, PRAGMA setters, BEGIN/COMMIT).
  void exec(const char* sql);
  // Rolls back the open transaction, if any; never throws (used on error paths).
  void rollbackQuietly() noexcept;
  std::int64_t lastInsertId() const;
  // Rows changed by the last INSERT, UPDATE or DELETE.
  int changes() const;

  // Throws core::Error "<path>: <what>: <SQLite's message>".
  [[noreturn]] void fail(std::string_view what) const;

 private:
  sqlite3* db_ = nullptr;
  std::string path_;
};

// One prepared statement. Bind indices are 1-based (SQLite's), column indices 0-based.
class Statement {
 public:
  Statement(Connection& connection, const char* sql);
  ~Statement();
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  Statement& bind(int index, std::int64_t value);
  Statement& bind(int index, double value);
  Statement& bind(int index, const std::string& value);
  Statement& bindBlob(int index, const void* data, std::size_t bytes);  // NULL when bytes == 0
  Statement& bindNull(int index);

  // Advances: true while a row is available, false when done. Throws on any error.
  bool step();
  // Runs a statement that returns no rows.
  void run();
  void reset();

  bool isNull(int column) const;
  std::int64_t int64(int column) const;
  double real(int column) const;
  std::string text(int column) const;
  // The blob's bytes, valid until the next step()/reset(); size 0 for NULL.
  const void* blobData(int column) const;
  std::size_t blobSize(int column) const;

 private:
  Connection& connection_;
  sqlite3_stmt* stmt_ = nullptr;
};

}  // namespace tessera::db::internal
