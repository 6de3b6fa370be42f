#pragma once
// Idle read connections of a store, lent one read at a time (SQLite's and PostgreSQL's stores
// keep one each). Thread-safe.
#include <memory>
#include <mutex>
#include <utility>
#include <vector>

namespace tessera::db::internal {

template <typename Connection>
class ConnectionPool {
 public:
  // A connection lent for one read: an idle one, or none when all are out (the borrower then
  // opens one into connection()). Given back when the lease ends, unless it was reset (a
  // broken connection).
  class Lease {
   public:
    explicit Lease(ConnectionPool& pool) : pool_(pool), connection_(pool.take()) {}
    ~Lease() {
      if (connection_) pool_.give(std::move(connection_));
    }
    Lease(const Lease&) = delete;
    Lease& operator=(const Lease&) = delete;
    std::unique_ptr<Connection>& connection() { return connection_; }

   private:
    ConnectionPool& pool_;
    std::unique_ptr<Connection> connection_;
  };

  void give(std::unique_ptr<Connection> connection) {
    const std::lock_guard lock(mutex_);
    idle_.push_back(std::move(connection));
  }
  void clear() {
    const std::lock_guard lock(mutex_);
    idle_.clear();
  }

 private:
  std::unique_ptr<Connection> take() {
    const std::lock_guard lock(mutex_);
    if (idle_.empty()) return nullptr;
    std::unique_ptr<Connection> connection = std::move(idle_.back());
    idle_.pop_back();
    return connection;
  }

  std::mutex mutex_;
  std::vector<std::unique_ptr<Connection>> idle_;
};

}  // namespace tessera::db::internal
