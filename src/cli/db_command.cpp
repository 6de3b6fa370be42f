#include "db_command.h"

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "stop_request.h"
#include "tessera/core/error.h"
#include "tessera/db/store_copy.h"
#include "tessera/db/store_prune.h"
#include "tessera/db/texture_store.h"
#include "tessera/db/texture_summary_json.h"
#include "tessera/match/match_cascade.h"
#include "tessera/monitor/monitor_server.h"
#include "tessera/pipeline/run_config.h"
#include "tessera/reuse/store_catalog.h"
#include "tessera/texture/bitmap_export.h"
#include "texture_image.h"

namespace tessera::cli {

namespace {

std::string provenance(const db::TextureSummary& t) {
  if (!t.name.empty()) return t.name;
  return fmt::format("run {} patch {}", t.run_id, t.source_patch);
}

int list(const db::TextureStore& store, bool json) {
  const std::vector<db::TextureSummary> textures = store.textures();
  if (json) {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& t : textures) out.push_back(db::summaryJson(t));
    fmt::print("{}\n", out.dump(2));
    return 0;
  }
  fmt::print("{:>6}  {:<8} {:>11}  {:>5}  {:>9}  {}\n", "id", "kind", "size", "uses", "PNG KB",
             "from");
  for (const auto& t : textures) {
    fmt::print("{:>6}  {:<8} {:>5}x{:<5}  {:>5}  {:>9.1f}  {}\n", t.id, db::kindName(t.kind),
               t.width, t.height, t.uses, static_cast<double>(t.png_bytes) / 1e3, provenance(t));
  }
  fmt::print("{} textures\n", textures.size());
  return 0;
}

int show(const db::TextureStore& store, std::int64_t id, bool json) {
  const std::optional<db::TextureRecord> record = store.texture(id);
  if (!record) {
    spdlog::error("{}: no texture {}", store.location(), id);
    return 1;
  }
  nlohmann::json uses = nlohmann::json::array();
  for (const db::TextureInstance& i : store.instances()) {
    if (i.texture_id != id) continue;
    uses.push_back({{"run_id", i.run_id},
                    {"patch_id", i.patch_id},
                    {"version", i.version},
                    {"layer", i.layer},
                    {"transform", {i.transform.a, i.transform.b, i.transform.tx, i.transform.ty}},
                    {"angle_deg", i.transform.angleRad() * 180.0 / M_PI},
                    {"scale", i.transform.scale()},
                    {"reused", i.reused},
                    {"psnr_db", i.psnr_db ? nlohmann::json(*i.psnr_db) : nullptr}});
  }
  nlohmann::json out = {{"id", record->id},
                        {"kind", db::kindName(record->kind)},
                        {"width", record->rgb.cols},
                        {"height", record->rgb.rows},
                        {"valid_texels", cv::countNonZero(record->mask)},
                        {"texel_m", record->texel_m},
                        {"features", record->feature_kind},
                        {"keypoints", record->keypoints.size()},
                        {"ccv_length", record->ccv.size()},
                        {"content_key", record->content_key},
                        {"run_id", record->run_id},
                        {"source_patch", record->source_patch},
                        {"name", record->name},
                        {"instances", uses}};
  out["lattice"] = record->lattice
                       ? nlohmann::json{{"v1", {record->lattice->v1.x(), record->lattice->v1.y()}},
                                        {"v2", {record->lattice->v2.x(), record->lattice->v2.y()}}}
                       : nlohmann::json(nullptr);
  if (json) {
    fmt::print("{}\n", out.dump(2));
  } else {
    for (const auto& [key, value] : out.items()) {
      if (key != "instances") fmt::print("{}: {}\n", key, value.dump());
    }
    fmt::print("instances: {}\n", uses.size());
    for (const auto& use : uses) fmt::print("  {}\n", use.dump());
  }
  return 0;
}

int exportAll(const db::TextureStore& store, const std::filesystem::path& out_dir) {
  std::error_code ec;
  std::filesystem::create_directories(out_dir, ec);
  if (ec)
    throw core::Error(fmt::format("{}: cannot be created: {}", out_dir.string(), ec.message()));
  nlohmann::json index = nlohmann::json::array();
  for (const db::TextureSummary& t : store.textures()) {
    const std::optional<db::TextureRecord> record = store.texture(t.id);
    if (!record) continue;
    const std::string file = fmt::format("texture_{}.png", t.id);
    texture::writeRgbaPng(out_dir / file, record->rgb, record->mask);
    nlohmann::json entry = db::summaryJson(t);
    entry["file"] = file;
    index.push_back(entry);
  }
  const std::filesystem::path index_path = out_dir / "textures.json";
  std::ofstream out(index_path);
  out << index.dump(2) << '\n';
  out.close();
  if (!out) throw core::Error(fmt::format("{}: could not be written", index_path.string()));
  fmt::print("{} textures written to {}\n", index.size(), out_dir.string());
  return 0;
}

int import(db::TextureStore& store, const DbArguments& args) {
  const pipeline::RunConfig config = pipeline::loadRunConfig(
      args.config.empty() ? std::nullopt : std::optional<std::filesystem::path>(args.config));
  for (const std::string& path : args.images) {
    cv::Mat rgb, mask;
    readTextureImage(path, rgb, mask);
    const match::TextureDescription description = match::describeTexture(rgb, mask, config.match);
    db::TextureRecord record = reuse::textureRecordOf(
        description, args.pattern ? db::TextureKind::kPattern : db::TextureKind::kSingle);
    if (args.pattern) {  // the image is one period in each direction
      record.lattice = db::Lattice{{rgb.cols, 0.0}, {0.0, rgb.rows}};
    }
    record.content_key = db::contentKey(rgb, mask);
    record.name = std::filesystem::path(path).filename().string();
    const std::optional<std::int64_t> existing = store.findByContentKey(record.content_key);
    if (existing) {
      fmt::print("{}: already stored as texture {}\n", path, *existing);
      continue;
    }
    const std::vector<std::int64_t> ids = store.commit({{record}, {}, {}});
    fmt::print("{}: texture {} ({}, {}x{}, {} keypoints)\n", path, ids.at(0),
               db::kindName(record.kind), rgb.cols, rgb.rows, record.keypoints.size());
  }
  return 0;
}

int stats(const db::TextureStore& store, bool json) {
  const db::StoreStats s = store.stats();
  const nlohmann::json out = {{"location", store.location()},
                              {"schema_version", s.schema_version},
                              {"textures", s.textures},
                              {"patterns", s.patterns},
                              {"instances", s.instances},
                              {"runs", s.runs},
                              {"texture_pixels", s.texture_pixels},
                              {"texture_mb_rgb", 3e-6 * static_cast<double>(s.texture_pixels)},
                              {"file_bytes", s.file_bytes}};
  if (json) {
    fmt::print("{}\n", out.dump(2));
  } else {
    for (const auto& [key, value] : out.items()) fmt::print("{}: {}\n", key, value.dump());
  }
  return 0;
}

// The monitor's server over the database alone: the page shows the gallery, no run.
int serve(const DbArguments& args) {
  const pipeline::MapMonitor idle;
  monitor::MonitorServerOptions options;
  options.listen = monitor::parseListenAddress(args.listen);
  options.token = args.token;
  options.db = args.db;
  monitor::MonitorServer server(idle, options);
  spdlog::info("serving {} on {}{}; Ctrl-C stops", args.db, server.url(),
               args.token.empty() ? "" : " (bearer token required)");
  const std::atomic<bool>& stop = stopOnInterrupt();
  while (!stop) std::this_thread::sleep_for(std::chrono::milliseconds(200));
  server.stop();
  return 0;
}

// Everything DB holds into DESTINATION (created if missing), with a progress line.
int copy(const db::TextureStore& from, const std::string& destination) {
  const std::unique_ptr<db::TextureStore> to = db::openTextureStore(destination);
  spdlog::info("copying {} into {}", from.location(), to->location());
  auto last = std::chrono::steady_clock::now();
  const db::CopyReport report =
      db::copyStore(from, *to, [&last](std::size_t done, std::size_t total) {
        const auto now = std::chrono::steady_clock::now();
        if (done < total && now - last < std::chrono::seconds(2)) return;
        last = now;
        spdlog::info("textures {} / {}", done, total);
      });
  fmt::print("{} runs copied ({} copied before), {} textures copied ({} already there), {} "
             "instances\n",
             report.runs_copied, report.runs_already_there, report.textures_copied,
             report.textures_already_there, report.instances_copied);
  return 0;
}

// Removes the textures finished runs stored that no instance uses (db::pruneUnused).
int prune(db::TextureStore& store) {
  const db::PruneReport report = db::pruneUnused(store);
  fmt::print("{} unused textures removed ({:.1f} MB of PNG), {} left\n", report.removed,
             static_cast<double>(report.png_bytes) / 1e6, report.textures_left);
  if (report.kept_unfinished > 0) {
    fmt::print("{} unused textures of runs not finished kept (a run still going may use them)\n",
               report.kept_unfinished);
  }
  return 0;
}

// Sends a journal a run left (its server was away at the end) to that server.
int flush(const DbArguments& args) {
  const db::ServerLink link = db::flushJournal(args.db, args.destination, args.wait_s);
  fmt::print("{} commits with {} new textures sent, {} refused, {} left\n",
             link.replayed_commits, link.replayed_textures, link.refused_commits,
             link.pending_commits);
  if (link.pending_commits > 0) {
    spdlog::error("{}: {} commits not sent within {:.0f} s (the server is away again?); they "
                  "stay in the journal",
                  args.db, link.pending_commits, args.wait_s);
    return 1;
  }
  return 0;
}

}  // namespace

CLI::App* addDbCommand(CLI::App& app, DbArguments& args) {
  CLI::App* db = app.add_subcommand("db", "Look into, export or fill a texture database");
  db->require_subcommand(1);
  // The store itself names a missing file, or a location it cannot open, clearly.
  auto add_db = [&args](CLI::App* sub) {
    sub->add_option("DB", args.db, "Texture database: SQLite file or postgresql:// URL")
        ->required();
  };
  CLI::App* list = db->add_subcommand("list", "One line per texture: kind, size, uses, origin");
  add_db(list);
  list->add_flag("--json", args.json, "Print a JSON array");
  CLI::App* show = db->add_subcommand("show", "Everything about one texture and its instances");
  add_db(show);
  show->add_option("ID", args.texture_id, "Texture id (as db list shows)")->required();
  show->add_flag("--json", args.json, "Print a JSON object");
  CLI::App* exp = db->add_subcommand(
      "export", "Write every texture as an RGBA PNG (alpha: valid texels) and textures.json");
  add_db(exp);
  exp->add_option("DIR", args.out_dir, "Folder to write to (created if needed)")->required();
  CLI::App* imp = db->add_subcommand(
      "import", "Add standard textures (images) to a database, created if missing");
  add_db(imp);
  imp->add_option("IMAGES", args.images, "Image files (PNG, JPEG, ...; alpha marks valid texels)")
      ->required()
      ->check(CLI::ExistingFile);
  imp->add_flag("--pattern", args.pattern,
                "Each image is one tile of a repeating pattern (found in new bitmaps by "
                "cross-correlation and repeated over the patch)");
  imp->add_option("--config", args.config, "YAML config whose match: keys describe the textures")
      ->check(CLI::ExistingFile);
  CLI::App* st = db->add_subcommand("stats", "Schema version, counts and sizes");
  add_db(st);
  st->add_flag("--json", args.json, "Print a JSON object");
  CLI::App* serve = db->add_subcommand(
      "serve", "Browse the database in a web browser (the run monitor's page, without a run) "
               "until Ctrl-C");
  add_db(serve);
  serve->add_option("--listen", args.listen,
                    "[ADDR:]PORT to serve on (ADDR 127.0.0.1 unless given; PORT 0 picks a free "
                    "one)")
      ->capture_default_str();
  serve->add_option("--token", args.token,
                    "Require this bearer token on every request (also read from "
                    "TESSERA_MONITOR_TOKEN)")
      ->envname("TESSERA_MONITOR_TOKEN");
  CLI::App* copy = db->add_subcommand(
      "copy", "Copy every run, texture and instance of DB into DESTINATION (SQLite or "
              "PostgreSQL, created if missing); copying again adds nothing twice");
  add_db(copy);
  copy->add_option("DESTINATION", args.destination,
                   "Database to copy into: SQLite file or postgresql:// URL")
      ->required();
  CLI::App* prune = db->add_subcommand(
      "prune",
      "Remove the textures finished runs stored that no instance uses (older versions "
      "of patches); imported textures stay");
  add_db(prune);
  CLI::App* flush = db->add_subcommand(
      "flush", "Send the commits a run left in OUT/db_journal.sqlite (its PostgreSQL server "
               "was away when it ended) to that server");
  flush->add_option("JOURNAL", args.db, "The journal (OUT/db_journal.sqlite)")
      ->required()
      ->check(CLI::ExistingFile);
  flush->add_option("--db", args.destination,
                    "The server's URL, when the journal's (which has no password) is not enough");
  flush->add_option("--wait", args.wait_s, "Seconds to wait for the server to take everything")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  return db;
}

int dbCommand(const CLI::App& db, const DbArguments& args) {
  try {
    const auto parsed = [&db](const char* name) { return db.get_subcommand(name)->parsed(); };
    if (parsed("flush")) return flush(args);
    const bool writes = parsed("import") || parsed("prune");
    const std::unique_ptr<db::TextureStore> store =
        db::openTextureStore(args.db, {writes, !writes});
    if (parsed("list")) return list(*store, args.json);
    if (parsed("show")) return show(*store, args.texture_id, args.json);
    if (parsed("export")) return exportAll(*store, args.out_dir);
    if (parsed("import")) return import(*store, args);
    if (parsed("serve")) return serve(args);
    if (parsed("copy")) return copy(*store, args.destination);
    if (parsed("prune")) return prune(*store);
    return stats(*store, args.json);
  } catch (const core::Error& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}

}  // namespace tessera::cli
