// What reuse costs the map, for a sweep of acceptance settings (match.min_psnr_db x
// match.min_coverage): the rate-distortion curve of texture reuse on a real sequence. For each
// setting the pipeline runs over SOURCE at its reference poses with matching on, and once with
// matching off (match.enabled: false); each map is scored by `tessera eval --frames` on the same
// frames. Prints per setting: reuses, patterns stored, compression, view PSNR and detail score
// of the patches on training and held-out views, and their loss against the run without
// matching. Each run's reuse sheet (RUN/reuse_sheet.png) is written for looking at every reuse:
// a false match is found there, by eye.
//
// With --split A,B the frames are cut into a first run (frames [0, A)) and a second run (frames
// [B, end)) sharing one texture database, as a robot's two sessions would: the figures are the
// second run's, and "reused" is the share of its textured patches shown through a texture the
// first run stored.
//
//   acceptance_bench [SOURCE] [--depth-scale UNITS_PER_M] [--psnr 28,25,22] [--coverage 0.85,0.6]
//                    [--split A,B] [--holdout-every 5] [--work DIR]
//
// SOURCE defaults to ../shared/data/rgbd/sun3d_studyroom_frag1 (depth scale 1000).
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "bench_frames.h"
#include "tessera/core/error.h"
#include "tessera/core/log.h"
#include "tessera/eval/reuse_sheet.h"
#include "tessera/eval/run_evaluation.h"
#include "tessera/pipeline/run.h"

namespace {

namespace fs = std::filesystem;
namespace pipeline = tessera::pipeline;
namespace core = tessera::core;

// The frames of `source` whose position in it lies in [begin, end).
class FrameWindow : public core::FrameSource {
 public:
  FrameWindow(std::unique_ptr<core::FrameSource> source, std::size_t begin, std::size_t end)
      : source_(std::move(source)), begin_(begin), end_(end) {}
  core::ReadResult read() override {
    for (;;) {
      if (position_ >= end_) return {};
      core::ReadResult result = source_->read();
      if (result.status == core::ReadStatus::kEndOfData) return result;
      if (position_++ >= begin_) return result;
    }
  }
  std::string name() const override { return source_->name(); }
  std::optional<std::size_t> frameCount() const override {
    const auto total = source_->frameCount();
    if (!total) return std::nullopt;
    const std::size_t last = std::min(*total, end_);
    return last > begin_ ? last - begin_ : 0;
  }

 private:
  std::unique_ptr<core::FrameSource> source_;
  std::size_t begin_, end_, position_ = 0;
};

struct Setting {
  bool matching = true;
  double min_psnr_db = 0.0, min_coverage = 0.0;
  std::string name() const {
    return matching ? fmt::format("psnr {:.0f} dB, coverage {:.2f}", min_psnr_db, min_coverage)
                    : std::string("matching off");
  }
};

struct Figures {
  int reuses = 0, patterns = 0, textured = 0;
  double compression = 1.0;
  double psnr = 0.0, psnr_held_out = 0.0, detail = 0.0, detail_held_out = 0.0;
};

double number(const nlohmann::json& j, const char* key) {
  return j.contains(key) && j[key].is_number() ? j[key].get<double>() : 0.0;
}

struct Bench {
  std::string source;
  std::optional<double> depth_scale;
  int holdout_every = 5;
  std::optional<std::pair<std::size_t, std::size_t>> split;
  fs::path work;

  std::unique_ptr<core::FrameSource> open(std::size_t begin, std::size_t end) const {
    return std::make_unique<FrameWindow>(tessera::bench::openSource(source, {}, depth_scale), begin,
                                         end);
  }

  pipeline::RunConfig configFor(const Setting& setting) const {
    pipeline::RunConfig config = pipeline::loadRunConfig(std::nullopt);
    config.match.enabled = setting.matching;
    if (setting.matching) {
      config.match.min_psnr_db = setting.min_psnr_db;
      config.match.min_coverage = setting.min_coverage;
    }
    return config;
  }

  // One run over frames [begin, end) into `out`, growing `db`; its figures.
  Figures run(const Setting& setting, std::size_t begin, std::size_t end, const fs::path& out,
              const fs::path& db) const {
    pipeline::RunOptions options;
    options.out_dir = out;
    options.db = db.string();
    options.poses = pipeline::PoseSource::kGroundTruth;
    options.holdout_every = holdout_every;
    const auto input = open(begin, end);
    pipeline::runPipeline(*input, configFor(setting), options);
    std::ifstream report_file(out / "report.json");
    const nlohmann::json report = nlohmann::json::parse(report_file);
    Figures f;
    f.reuses = static_cast<int>(number(report, "reuses"));
    f.patterns = static_cast<int>(number(report, "patterns_stored"));
    f.textured = static_cast<int>(number(report, "patches_finalized"));
    f.compression = number(report, "compression");
    tessera::eval::ViewEvaluationOptions view_options;
    const auto frames = open(begin, end);
    const nlohmann::json views = tessera::eval::evaluateRunViews(out, *frames, view_options);
    f.psnr = number(views, "view_psnr_mean");
    f.psnr_held_out = number(views, "view_psnr_holdout_mean");
    f.detail = number(views, "view_detail_mean");
    f.detail_held_out = number(views, "view_detail_holdout_mean");
    if (setting.matching) tessera::eval::writeReuseSheet(out);
    return f;
  }

  // The figures of `setting`: of the whole sequence, or of the split's second run.
  Figures measure(const Setting& setting, const std::string& tag) const {
    const fs::path dir = work / tag;
    fs::remove_all(dir);
    fs::create_directories(dir);
    const fs::path db = dir / "textures.db";
    constexpr std::size_t kAll = static_cast<std::size_t>(-1);
    if (!split) return run(setting, 0, kAll, dir / "run", db);
    run(setting, 0, split->first, dir / "first", db);
    return run(setting, split->second, kAll, dir / "second", db);
  }
};

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Rate-distortion of texture reuse over a sweep of acceptance settings"};
  Bench bench;
  std::vector<double> psnrs{28.0, 25.0, 22.0}, coverages{0.85, 0.6};
  std::vector<std::size_t> split;
  bench.work = fs::temp_directory_path() / "tessera_acceptance_bench";
  app.add_option("SOURCE", bench.source, "Dataset folder with reference poses");
  app.add_option("--depth-scale", bench.depth_scale, "Raw depth units per metre");
  app.add_option("--psnr", psnrs, "match.min_psnr_db values to sweep")->delimiter(',');
  app.add_option("--coverage", coverages, "match.min_coverage values to sweep")->delimiter(',');
  app.add_option("--split", split,
                 "A,B: a first run over frames [0, A), then a second run over "
                 "[B, end) with the same database; the second run's figures")
      ->delimiter(',')
      ->expected(2);
  app.add_option("--holdout-every", bench.holdout_every, "Held-out views for the view figures");
  app.add_option("--work", bench.work, "Folder for the runs (each run's reuse_sheet.png)");
  CLI11_PARSE(app, argc, argv);
  if (bench.source.empty()) {
    bench.source = (fs::path(TESSERA_SHARED_DATA_DIR) / "rgbd/sun3d_studyroom_frag1").string();
    if (!bench.depth_scale) bench.depth_scale = 1000.0;
  }
  if (!split.empty()) bench.split = std::pair{split[0], split[1]};
  tessera::core::initLogging("warn");

  try {
    fmt::print("acceptance_bench: {}{}, reference poses, every {}th frame held out\n", bench.source,
               bench.split ? fmt::format(" split: frames [0, {}) then [{}, end), one database; "
                                         "figures of the second run",
                                         bench.split->first, bench.split->second)
                           : "",
               bench.holdout_every);
    const Figures off = bench.measure({false, 0.0, 0.0}, "matching_off");
    fmt::print("{:<28} {:>6} {:>8} {:>11} {:>15} {:>15} {:>9} {:>9}\n", "setting", "reused",
               "patterns", "compression", "view PSNR dB", "held out dB", "detail", "lost dB");
    const auto row = [&](const Setting& s, const Figures& f) {
      fmt::print("{:<28} {:>3}/{:<3} {:>7} {:>10.2f}x {:>15.2f} {:>15.2f} {:>9.3f} {:>9.2f}\n",
                 s.name(), f.reuses, f.textured, f.patterns, f.compression, f.psnr, f.psnr_held_out,
                 f.detail, off.psnr - f.psnr);
    };
    row({false, 0.0, 0.0}, off);
    nlohmann::json curve = nlohmann::json::array();
    for (const double psnr : psnrs) {
      for (const double coverage : coverages) {
        const Setting setting{true, psnr, coverage};
        const Figures f =
            bench.measure(setting, fmt::format("psnr{:.0f}_cov{:.0f}", psnr, 100.0 * coverage));
        row(setting, f);
        curve.push_back({{"min_psnr_db", psnr},
                         {"min_coverage", coverage},
                         {"reuses", f.reuses},
                         {"patches", f.textured},
                         {"compression", f.compression},
                         {"view_psnr", f.psnr},
                         {"view_psnr_lost", off.psnr - f.psnr},
                         {"view_psnr_holdout_lost", off.psnr_held_out - f.psnr_held_out},
                         {"detail_lost", off.detail - f.detail}});
      }
    }
    fmt::print("reuse sheets: {}/*/*/reuse_sheet.png\n", bench.work.string());
    fmt::print("json: {}\n", curve.dump());
  } catch (const std::exception& e) {
    fmt::print(stderr, "acceptance_bench: {}\n", e.what());
    return 1;
  }
  return 0;
}
