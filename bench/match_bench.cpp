// Matching latency and quality against a texture database of N textures, generated from the
// shared texture sets (../shared/data/textures): each source image is tiled to a 256 px base,
// stored under one exposure, and queried as a crop of it turned by a random angle, scaled by
// 0.8 to 1.25, under another exposure and with sensor-like noise. Half the queries come from
// sources in the database (a true match exists), half from sources left out (none does).
//
// The first --described textures are stored whole (pixels, CCV, SIFT). For larger databases the
// others are CCV vectors mixed from two described ones (weights at random), whose pixels and
// features, when the prefilter lets one through, are those of the nearer of the two: the index
// and the cascade do their real work on every candidate, without describing or holding 100,000
// images.
//
//   match_bench [--textures N] [--described M] [--queries Q] [--seed S] [--data DIR]
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <map>
#include <random>

#include <fmt/format.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/match/match_cascade.h"

namespace {

namespace fs = std::filesystem;
using tessera::match::StoredTexture;

std::vector<cv::Mat> loadSources(const fs::path& dir) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (entry.path().extension() == ".png") files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  std::vector<cv::Mat> sources;
  for (const fs::path& file : files) {
    cv::Mat bgr = cv::imread(file.string(), cv::IMREAD_COLOR);
    if (bgr.empty()) continue;
    cv::Mat rgb;
    cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
    // Tile small (seamless) images up to a 256 px base, as a wall repeats its tile.
    cv::Mat base;
    cv::repeat(rgb, (255 + rgb.rows) / rgb.rows, (255 + rgb.cols) / rgb.cols, base);
    sources.push_back(base(cv::Rect(0, 0, 256, 256)).clone());
  }
  return sources;
}

cv::Mat exposed(const cv::Mat& rgb, double gain, double noise, std::mt19937& random) {
  cv::Mat out;
  rgb.convertTo(out, CV_32FC3, gain);
  if (noise > 0.0) {
    cv::Mat n(out.size(), CV_32FC3);
    cv::randn(n, 0.0, noise);
    out += n;
  }
  out.convertTo(out, CV_8UC3);
  (void)random;
  return out;
}

// A crop of `base` seen through a random similarity: (rgb, mask).
std::pair<cv::Mat, cv::Mat> warpedCrop(const cv::Mat& base, int size, std::mt19937& random) {
  std::uniform_real_distribution<double> angle(-180.0, 180.0), scale(0.8, 1.25), gain(0.8, 1.2);
  std::uniform_real_distribution<double> offset(-30.0, 30.0);
  const cv::Point2f centre(static_cast<float>(base.cols / 2.0 + offset(random)),
                           static_cast<float>(base.rows / 2.0 + offset(random)));
  cv::Mat M = cv::getRotationMatrix2D(centre, angle(random), scale(random));
  M.at<double>(0, 2) += size / 2.0 - centre.x;
  M.at<double>(1, 2) += size / 2.0 - centre.y;
  cv::Mat rgb, mask;
  cv::warpAffine(base, rgb, M, {size, size}, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
  cv::warpAffine(cv::Mat(base.size(), CV_8UC1, cv::Scalar(255)), mask, M, {size, size},
                 cv::INTER_NEAREST, cv::BORDER_CONSTANT);
  return {exposed(rgb, gain(random), 3.0, random), mask};
}

// Textures in memory; ids above the described ones lend a described texture's pixels.
class BenchCatalog : public tessera::match::TextureCatalog {
 public:
  explicit BenchCatalog(const tessera::match::CcvConfig& config)
      : index_(tessera::match::ccvLength(config)) {}
  void add(std::int64_t id, const std::vector<float>& ccv,
           std::shared_ptr<const StoredTexture> body) {
    index_.add(id, ccv);
    bodies_[id] = std::move(body);
  }
  std::size_t size() const override { return index_.size(); }
  std::vector<tessera::match::CcvNeighbour> nearest(const std::vector<float>& ccv, double d,
                                                    std::size_t k) const override {
    return index_.query(ccv, d, k);
  }
  std::shared_ptr<const StoredTexture> load(std::int64_t id) const override {
    const auto it = bodies_.find(id);
    if (it == bodies_.end()) return nullptr;
    auto lent = std::make_shared<StoredTexture>(*it->second);
    lent->id = id;
    return lent;
  }

 private:
  tessera::match::CcvIndex index_;
  std::map<std::int64_t, std::shared_ptr<const StoredTexture>> bodies_;
};

double percentileOf(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())))];
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Matching latency and quality against a database of N generated textures"};
  std::size_t textures = 1000, described = 1000, queries = 200;
  unsigned seed = 7;
  std::string data = TESSERA_SHARED_DATA_DIR "/textures";
  app.add_option("--textures", textures, "Textures in the database")->capture_default_str();
  app.add_option("--described", described, "Of which stored whole (pixels and features)")
      ->capture_default_str();
  app.add_option("--queries", queries, "New bitmaps to match")->capture_default_str();
  app.add_option("--seed", seed, "Random seed")->capture_default_str();
  app.add_option("--data", data, "Texture folder")->capture_default_str();
  tessera::match::MatchConfig config;
  app.add_option("--max-candidates", config.max_candidates, "Candidates past the CCV prefilter")
      ->capture_default_str();
  app.add_option("--max-features", config.features.max_features, "Keypoints per texture")
      ->capture_default_str();
  app.add_option("--ccv-max-distance", config.ccv_max_distance, "The CCV prefilter's bound")
      ->capture_default_str();
  app.add_option("--detector", config.features.detector, "sift, orb or akaze")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  cv::setNumThreads(1);  // latency of one matcher on one core

  const std::vector<cv::Mat> sources = loadSources(data);
  if (sources.size() < 4) {
    fmt::print(stderr, "{}: fewer than 4 PNG textures found\n", data);
    return 1;
  }
  const tessera::match::MatchCascade cascade(config);
  std::mt19937 random(seed);
  // Every 4th source is left out of the database: its queries have no true match.
  auto stored_source = [&](std::size_t i) { return i % 4 != 3; };
  std::vector<std::size_t> in_db;
  for (std::size_t i = 0; i < sources.size(); ++i) {
    if (stored_source(i)) in_db.push_back(i);
  }
  BenchCatalog catalog(config.ccv);
  std::map<std::int64_t, std::size_t> source_of;
  std::map<std::size_t, std::shared_ptr<const StoredTexture>> body_of_source;
  std::uniform_real_distribution<double> gain(0.8, 1.2);
  const auto build_start = std::chrono::steady_clock::now();
  for (std::size_t t = 0; t < textures; ++t) {
    const std::size_t source = in_db[t % in_db.size()];
    const auto id = static_cast<std::int64_t>(t + 1);
    source_of[id] = source;
    if (t < described) {
      auto stored = std::make_shared<StoredTexture>();
      stored->id = id;
      const cv::Mat rgb = exposed(sources[source], gain(random), 2.0, random);
      stored->description = tessera::match::describeTexture(rgb, cv::Mat(), config);
      if (!body_of_source.count(source)) body_of_source[source] = stored;
      catalog.add(id, stored->description.ccv.values, stored);
    } else {
      // A mixture of two described textures' vectors (itself a valid CCV: the shares still sum
      // to 1): as varied as real vectors, at no cost per texture.
      const std::int64_t a = 1 + static_cast<std::int64_t>(random() % described);
      const std::int64_t b = 1 + static_cast<std::int64_t>(random() % described);
      const auto& va = catalog.load(a)->description.ccv.values;
      const auto& vb = catalog.load(b)->description.ccv.values;
      const float w = std::uniform_real_distribution<float>(0.0F, 1.0F)(random);
      std::vector<float> mixed(va.size());
      for (std::size_t i = 0; i < va.size(); ++i) mixed[i] = w * va[i] + (1.0F - w) * vb[i];
      source_of[id] = source_of[w >= 0.5F ? a : b];
      catalog.add(id, mixed, body_of_source.at(source_of[id]));
    }
    if ((t + 1) % 10000 == 0) fmt::print(stderr, "\r{} textures", t + 1);
  }
  const double build_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - build_start).count();

  std::vector<double> latency, prefilter_ms;
  std::size_t considered = 0, removed = 0, true_queries = 0, found = 0, false_matches = 0,
              true_rejected = 0, twin_matches = 0;
  // Some files of the sets hold one texture twice (a copy turned by 90 degrees, animation frames
  // of one flat): a reuse across them is right when the cascade, on the clean images, finds the
  // one inside the other at the fidelity of an exact copy.
  const auto sameTexture = [&](std::size_t a, std::size_t b) {
    StoredTexture other;
    other.description = tessera::match::describeTexture(sources[b], cv::Mat(), config);
    const cv::Mat crop = sources[a](cv::Rect(64, 64, 128, 128)).clone();
    const auto verdict =
        cascade.tryCandidate(tessera::match::describeTexture(crop, cv::Mat(), config), other, 0.0);
    return verdict.accepted && verdict.psnr_db >= 30.0;
  };
  for (std::size_t q = 0; q < queries; ++q) {
    const std::size_t source =
        (q % 2 == 0) ? in_db[random() % in_db.size()] : (random() % (sources.size() / 4)) * 4 + 3;
    if (source >= sources.size()) continue;
    const auto [rgb, mask] = warpedCrop(sources[source], 128, random);
    const tessera::match::TextureDescription query =
        tessera::match::describeTexture(rgb, mask, config);
    const auto p0 = std::chrono::steady_clock::now();
    const auto neighbours =
        catalog.nearest(query.ccv.values, config.ccv_max_distance, config.max_candidates);
    prefilter_ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - p0).count());
    const tessera::match::MatchDecision decision = cascade.match(query, catalog);
    latency.push_back(decision.ms);
    considered += decision.considered;
    removed += decision.considered - decision.passed_ccv;
    const bool has_truth = stored_source(source);
    true_queries += has_truth ? 1 : 0;
    if (has_truth) {
      const bool any_true = std::any_of(neighbours.begin(), neighbours.end(),
                                        [&](const auto& n) { return source_of[n.id] == source; });
      true_rejected += any_true ? 0 : 1;
    }
    if (decision.match) {
      if (source_of[decision.match->id] == source) {
        ++found;
      } else if (sameTexture(source, source_of[decision.match->id])) {
        ++twin_matches;  // another file of the same texture: correct
      } else {
        ++false_matches;
        fmt::print(stderr,
                   "false match: query from source {} reused texture {} of source {} ({}, "
                   "PSNR {:.1f} dB, coverage {:.2f}, CCV {:.2f})\n",
                   source, decision.match->id, source_of[decision.match->id],
                   decision.match->method, decision.match->psnr_db, decision.match->coverage,
                   decision.match->ccv_distance);
      }
    }
  }
  const nlohmann::json figures = {
      {"textures", textures},
      {"described", std::min(described, textures)},
      {"sources", sources.size()},
      {"queries", latency.size()},
      {"build_s", build_s},
      {"match_ms_p50", percentileOf(latency, 0.5)},
      {"match_ms_p95", percentileOf(latency, 0.95)},
      {"prefilter_ms_p50", percentileOf(prefilter_ms, 0.5)},
      {"ccv_rejection",
       considered > 0 ? static_cast<double>(removed) / static_cast<double>(considered) : 0.0},
      {"true_queries", true_queries},
      {"found", found + twin_matches},
      {"missed_rate", true_queries > 0
                          ? 1.0 - static_cast<double>(found) / static_cast<double>(true_queries)
                          : 0.0},
      {"true_lost_by_prefilter", true_rejected},
      {"false_matches", false_matches},
      {"matches_of_a_twin_file", twin_matches},
      {"false_match_rate",
       found + false_matches > 0
           ? static_cast<double>(false_matches) / static_cast<double>(found + false_matches)
           : 0.0}};
  fmt::print(stderr, "\n");
  fmt::print(
      "match latency over {} queries against {} textures: median {:.1f} ms, p95 {:.1f} ms "
      "(CCV index {:.2f} ms)\n",
      latency.size(), textures, percentileOf(latency, 0.5), percentileOf(latency, 0.95),
      percentileOf(prefilter_ms, 0.5));
  fmt::print(
      "found {} of {} true matches ({} lost to the prefilter), {} false matches, CCV "
      "rejection {:.1f} %\n",
      found, true_queries, true_rejected, false_matches,
      100.0 * figures["ccv_rejection"].get<double>());
  fmt::print("{}\n", figures.dump());
  return 0;
}
