#include "internal/queued_server_store.h"

#include <algorithm>
#include <atomic>
#include <map>
#include <system_error>

#include <unistd.h>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "internal/postgres_open.h"
#include "tessera/core/error.h"

namespace tessera::db::internal {

namespace {

constexpr std::chrono::milliseconds kFirstRetry{250};
constexpr std::chrono::milliseconds kLongestRetry{5000};

}  // namespace

QueuedServerStore::QueuedServerStore(std::unique_ptr<TextureStore> server,
                                     const std::filesystem::path& journal,
                                     const OpenOptions& options)
    : server_(std::move(server)),
      journal_(std::make_unique<CommitJournal>(journal, server_->location(),
                                               options.journal_max_mb << 20)),
      finish_wait_(options.finish_wait_s) {
  link_.journal = journal.string();
  if (const std::size_t left = journal_->entries(); left > 0) {
    spdlog::info("{}: sending {} commits an earlier run left in {}", server_->location(), left,
                 link_.journal);
  }
  sender_ = std::thread([this] { sendLoop(); });
}

QueuedServerStore::~QueuedServerStore() {
  {
    const std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  sender_.join();
  const std::size_t left = journal_->entries();
  journal_.reset();
  if (left == 0) {
    std::error_code ignored;
    std::filesystem::remove(link_.journal, ignored);
    return;
  }
  spdlog::warn("{}: {} commits could not be sent and are kept in {}; `tessera db flush {}` "
               "sends them when the server is back",
               server_->location(), left, link_.journal, link_.journal);
}

std::int64_t QueuedServerStore::beginRun(const std::string& source) {
  return server_->beginRun(source);  // a run needs its id from the server: no queueing
}

void QueuedServerStore::noteOutage(const std::string& why) {
  if (down_) return;
  down_ = true;
  down_since_ = std::chrono::steady_clock::now();
  ++link_.outages;
  spdlog::warn("{}; commits wait in {} until it is back", why, link_.journal);
}

void QueuedServerStore::noteBack() {
  if (!down_) return;
  down_ = false;
  const double away_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - down_since_).count();
  link_.disconnected_s += away_s;
  spdlog::info("{}: back after {:.1f} s; {} commits with {} new textures sent from the journal",
               server_->location(), away_s, link_.replayed_commits, link_.replayed_textures);
}

Commit QueuedServerStore::withServerIds(const Commit& commit) const {
  Commit out = commit;
  for (TextureInstance& instance : out.instances) {
    if (!isProvisional(instance.texture_id)) continue;
    const auto sent = journal_->serverId(instance.texture_id);
    if (!sent) return commit;  // still queued: so is this commit, which keeps the id
    instance.texture_id = *sent;
  }
  return out;
}

std::vector<std::int64_t> QueuedServerStore::commit(const Commit& commit) {
  std::unique_lock lock(mutex_);
  const Commit translated = withServerIds(commit);
  if (!down_ && journal_->entries() == 0) {
    try {
      return server_->commit(translated);
    } catch (const ServerUnavailable& e) {
      noteOutage(e.what());
    }
  }
  std::vector<EncodedTexture> encoded;
  encoded.reserve(translated.textures.size());
  for (std::size_t i = 0; i < translated.textures.size(); ++i) {
    encoded.push_back(encodeTexture(translated.textures[i], link_.journal, i));
  }
  std::vector<std::int64_t> ids = journal_->append(translated, encoded);
  ++link_.queued_commits;
  lock.unlock();
  wake_.notify_all();
  return ids;
}

std::vector<std::int64_t> QueuedServerStore::removeUnused(
    std::int64_t run_id, const std::vector<std::int64_t>& candidates) {
  // Only once the server has every commit: a queued commit may still use a candidate, and a
  // texture still in the journal has no server id yet. Until then they wait for the run's end.
  const std::lock_guard lock(mutex_);
  if (down_ || journal_->entries() > 0) {
    std::vector<std::int64_t>& later = deferred_removals_[run_id];
    later.insert(later.end(), candidates.begin(), candidates.end());
    return {};
  }
  return removeOnServer(run_id, candidates);
}

std::vector<std::int64_t> QueuedServerStore::removeOnServer(
    std::int64_t run_id, const std::vector<std::int64_t>& candidates) {
  std::map<std::int64_t, std::int64_t> given;  // server id -> the id the caller knows
  std::vector<std::int64_t> on_server;
  for (const std::int64_t id : candidates) {
    const std::optional<std::int64_t> sent = isProvisional(id) ? journal_->serverId(id) : id;
    if (!sent) continue;
    given[*sent] = id;
    on_server.push_back(*sent);
  }
  std::vector<std::int64_t> removed;
  try {
    for (const std::int64_t id : server_->removeUnused(run_id, on_server)) {
      removed.push_back(given.at(id));
    }
  } catch (const ServerUnavailable& e) {
    // Not an outage to queue for: the next commit finds out. They are tried again at the run's
    // end; what is still stored then stays, unused, until the owner's `tessera db prune`.
    spdlog::debug("{}: unused textures not removed yet: {}", server_->location(), e.what());
    std::vector<std::int64_t>& later = deferred_removals_[run_id];
    later.insert(later.end(), candidates.begin(), candidates.end());
  }
  std::sort(removed.begin(), removed.end());
  return removed;
}

void QueuedServerStore::finishRun(std::int64_t run_id) {
  std::unique_lock lock(mutex_);
  emptied_.wait_for(lock, finish_wait_, [&] { return journal_->entries() == 0; });
  if (journal_->entries() == 0) {
    if (const auto later = deferred_removals_.extract(run_id)) {
      // The run commits nothing more, so none of these can be wanted again.
      link_.removed_at_end += removeOnServer(run_id, later.mapped()).size();
    }
    try {
      server_->finishRun(run_id);
      return;
    } catch (const ServerUnavailable& e) {
      noteOutage(e.what());
    }
  }
  journal_->appendFinish(run_id);
  ++link_.queued_commits;
  spdlog::warn("{}: still away after {:.0f} s; {} commits wait in {}", server_->location(),
               finish_wait_.count(), journal_->entries(), link_.journal);
}

void QueuedServerStore::sendLoop() {
  std::unique_lock lock(mutex_);
  std::chrono::milliseconds retry = kFirstRetry;
  while (!stopping_) {
    std::optional<JournalEntry> entry;
    try {
      entry = journal_->oldest();
    } catch (const core::Error& e) {
      spdlog::error("{}: cannot read the journal: {}; its commits stay there", link_.journal,
                    e.what());
      return;
    }
    if (!entry) {
      noteBack();
      emptied_.notify_all();
      wake_.wait(lock, [&] { return stopping_ || journal_->entries() > 0; });
      continue;
    }
    // The network call runs unlocked: commits keep queueing behind this entry meanwhile.
    lock.unlock();
    std::vector<std::int64_t> ids;
    std::optional<std::string> lost, refused;
    try {
      if (entry->finish_run) {
        server_->finishRun(*entry->finish_run);
      } else {
        ids = server_->commit(entry->commit);
      }
    } catch (const ServerUnavailable& e) {
      lost = e.what();
    } catch (const core::Error& e) {
      refused = e.what();
    }
    lock.lock();
    if (lost) {
      noteOutage(*lost);
      wake_.wait_for(lock, retry, [&] { return stopping_; });
      retry = std::min(retry * 2, kLongestRetry);
      continue;
    }
    retry = kFirstRetry;
    if (refused) {
      // Sending it again would be refused again; the rest of the journal still goes.
      spdlog::error("{}: a queued commit was refused and is dropped: {}", link_.journal,
                    *refused);
      ++link_.refused_commits;
    } else {
      ++link_.replayed_commits;
      link_.replayed_textures += ids.size();
    }
    try {
      journal_->remove(*entry, ids);
    } catch (const core::Error& e) {
      spdlog::error("{}: cannot update the journal: {}", link_.journal, e.what());
      return;
    }
  }
}

std::optional<std::int64_t> QueuedServerStore::findByContentKey(const std::string& key) const {
  {
    const std::lock_guard lock(mutex_);
    if (const auto queued = journal_->findByContentKey(key)) return queued;
  }
  try {
    return server_->findByContentKey(key);
  } catch (const ServerUnavailable&) {
    return std::nullopt;  // stored as new; the server keeps one copy when it takes it
  }
}

std::optional<TextureRecord> QueuedServerStore::texture(std::int64_t id) const {
  if (!isProvisional(id)) return server_->texture(id);
  std::optional<std::int64_t> sent;
  {
    const std::lock_guard lock(mutex_);
    if (auto queued = journal_->texture(id)) return queued;
    sent = journal_->serverId(id);
  }
  if (!sent) return std::nullopt;
  auto record = server_->texture(*sent);
  if (record) record->id = id;  // as the caller knows it
  return record;
}

std::vector<CcvEntry> QueuedServerStore::ccvVectors(std::int64_t after_id) const {
  return server_->ccvVectors(after_id);
}

std::vector<TextureSummary> QueuedServerStore::textures() const { return server_->textures(); }

std::vector<TextureInstance> QueuedServerStore::instances(
    std::optional<std::int64_t> run_id) const {
  return server_->instances(run_id);
}

std::vector<RunRecord> QueuedServerStore::runs() const { return server_->runs(); }

StoreStats QueuedServerStore::stats() const { return server_->stats(); }

std::int64_t QueuedServerStore::resolvedId(std::int64_t id) const {
  if (!isProvisional(id)) return id;
  const std::lock_guard lock(mutex_);
  return journal_->serverId(id).value_or(id);
}

std::optional<ServerLink> QueuedServerStore::serverLink() const {
  const std::lock_guard lock(mutex_);
  ServerLink link = link_;
  if (down_) {
    link.disconnected_s +=
        std::chrono::duration<double>(std::chrono::steady_clock::now() - down_since_).count();
  }
  link.pending_commits = journal_->entries();
  return link;
}

}  // namespace tessera::db::internal

namespace tessera::db {

std::unique_ptr<TextureStore> queueWhileAway(std::unique_ptr<TextureStore> server,
                                             const OpenOptions& options) {
  std::filesystem::path journal = options.journal;
  if (journal.empty()) {
    // Process, time and a count: stores opened by one process in the same millisecond (a
    // fleet's writers in one test, say) each get a journal of their own.
    static std::atomic<int> opened{0};
    const auto now = std::chrono::system_clock::now().time_since_epoch();
    journal =
        std::filesystem::temp_directory_path() /
        fmt::format("tessera-journal-{}-{}-{}.sqlite", ::getpid(),
                    std::chrono::duration_cast<std::chrono::milliseconds>(now).count(), opened++);
  }
  return std::make_unique<internal::QueuedServerStore>(std::move(server), journal, options);
}

ServerLink flushJournal(const std::filesystem::path& journal, const std::string& server,
                        double wait_s) {
  const std::string written_for = internal::CommitJournal::serverOf(journal);
  if (!internal::isPostgresUrl(written_for)) {
    throw core::Error(fmt::format("{}: written for '{}', which is not a server's URL",
                                  journal.string(), written_for));
  }
  OpenOptions options;
  options.create = false;
  options.journal = journal;
  // (The journal refuses a server other than its own, so a URL given here can only add a
  // password.)
  const std::unique_ptr<TextureStore> store =
      openTextureStore(server.empty() ? written_for : server, options);
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(wait_s);
  ServerLink link = *store->serverLink();
  while (link.pending_commits > 0 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    link = *store->serverLink();
  }
  return link;
}

}  // namespace tessera::db
