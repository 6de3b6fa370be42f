#include "tessera/drivers/synthetic/texture.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <random>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "internal/noise.h"
#include "tessera/core/error.h"

namespace tessera::drivers::synthetic {

namespace {

cv::Vec3f readColour(const core::ConfigSection& entry, const char* key, cv::Vec3f fallback) {
  std::vector<double> rgb;
  entry.read(key, rgb);
  if (rgb.empty()) return fallback;
  if (rgb.size() != 3) {
    throw core::ConfigError(
        fmt::format("{}: {}.{} must be [r, g, b] in 0..255", entry.origin(), entry.path(), key));
  }
  return {static_cast<float>(rgb[0]), static_cast<float>(rgb[1]), static_cast<float>(rgb[2])};
}

double positive(const core::ConfigSection& entry, const char* key, double value) {
  entry.read(key, value);
  if (!(value > 0.0)) {
    throw core::ConfigError(
        fmt::format("{}: {}.{} must be positive", entry.origin(), entry.path(), key));
  }
  return value;
}

std::uint32_t seedOf(const core::ConfigSection& entry) {
  int seed = 1;
  entry.read("seed", seed);
  return static_cast<std::uint32_t>(seed);
}

cv::Vec3f scaled(cv::Vec3f c, double factor) { return c * static_cast<float>(factor); }

// Index modulo n that is non-negative for negative indices.
std::int64_t wrap(std::int64_t i, std::int64_t n) { return ((i % n) + n) % n; }

// Running-bond brick: course c is shifted by half a brick against course c-1, so a brick sits
// at j * (P, 0) + c * (P / 2, H) with P, H the brick pitch. The look of a brick depends on
// j mod n only, which makes {(n P, 0), (P / 2, H)} the exact period lattice: the two
// interleaved courses of the published method.
class BrickTexture : public Texture {
 public:
  explicit BrickTexture(const core::ConfigSection& e)
      : Texture("brick"),
        width_(positive(e, "brick_width_m", 0.215)),
        height_(positive(e, "brick_height_m", 0.065)),
        mortar_(positive(e, "mortar_m", 0.01)),
        brick_(readColour(e, "colour", {150, 62, 44})),
        mortar_colour_(readColour(e, "mortar_colour", {190, 185, 175})),
        seed_(seedOf(e)) {
    e.read("bricks_per_period", n_);
    e.read("variation", variation_);
    if (n_ < 1)
      throw core::ConfigError(
          fmt::format("{}: {}.bricks_per_period must be >= 1", e.origin(), e.path()));
  }

  cv::Vec3f colour(double s, double t) const override {
    const double P = width_ + mortar_, H = height_ + mortar_;
    const double c = std::floor(t / H);
    const double shifted = s - c * P / 2;
    const double j = std::floor(shifted / P);
    const double x = shifted - j * P, y = t - c * H;
    const auto look = static_cast<std::int64_t>(wrap(static_cast<std::int64_t>(j), n_));
    // Fine texture in the brick's own coordinates, keyed by its look: repeats exactly.
    const double grain =
        noise::fractal(x / 0.004, y / 0.004, seed_ + static_cast<std::uint32_t>(look) * 7919u, 3);
    if (x > width_ || y > height_) return scaled(mortar_colour_, 0.9 + 0.2 * grain);
    const double tone = 1.0 + variation_ * (noise::unit(look, 0, seed_) - 0.5);
    return scaled(brick_, tone * (0.85 + 0.3 * grain));
  }

  std::optional<Lattice> lattice() const override {
    const double P = width_ + mortar_, H = height_ + mortar_;
    return Lattice{Eigen::Vector2d(n_ * P, 0.0), Eigen::Vector2d(P / 2, H)};
  }

 private:
  double width_, height_, mortar_;
  cv::Vec3f brick_, mortar_colour_;
  std::uint32_t seed_;
  int n_ = 3;
  double variation_ = 0.35;
};

// Square floor tiles with grout; tile (i, j) looks like tile (i mod n, j mod n).
class TileTexture : public Texture {
 public:
  explicit TileTexture(const core::ConfigSection& e)
      : Texture("tiles"),
        tile_(positive(e, "tile_m", 0.3)),
        grout_(positive(e, "grout_m", 0.006)),
        a_(readColour(e, "colour", {205, 200, 190})),
        b_(readColour(e, "second_colour", {120, 110, 100})),
        grout_colour_(readColour(e, "grout_colour", {90, 90, 90})),
        seed_(seedOf(e)) {
    e.read("tiles_per_period", n_);
    if (n_ < 1)
      throw core::ConfigError(
          fmt::format("{}: {}.tiles_per_period must be >= 1", e.origin(), e.path()));
  }

  cv::Vec3f colour(double s, double t) const override {
    const double i = std::floor(s / tile_), j = std::floor(t / tile_);
    const double x = s - i * tile_, y = t - j * tile_;
    const auto li = wrap(static_cast<std::int64_t>(i), n_),
               lj = wrap(static_cast<std::int64_t>(j), n_);
    const std::uint32_t key = seed_ + static_cast<std::uint32_t>(li * 131 + lj);
    if (x < grout_ || y < grout_)
      return scaled(grout_colour_, 0.9 + 0.2 * noise::value(x / 0.003, y / 0.003, key));
    // Two-colour checker inside the period, with a marbled vein pattern per tile.
    const cv::Vec3f base = ((li + lj) % 2 == 0) ? a_ : b_;
    const double vein = noise::fractal(x / 0.03, y / 0.03, key, 4);
    return scaled(base, 0.8 + 0.4 * vein);
  }

  std::optional<Lattice> lattice() const override {
    // With an even n the checker repeats after n tiles; with n odd after 2n.
    const double period = tile_ * static_cast<double>(n_ % 2 == 0 ? n_ : 2 * n_);
    return Lattice{Eigen::Vector2d(period, 0.0), Eigen::Vector2d(0.0, period)};
  }

 private:
  double tile_, grout_;
  cv::Vec3f a_, b_, grout_colour_;
  std::uint32_t seed_;
  int n_ = 2;
};

// Cobblestones: a Voronoi pattern of stones on a torus of side `period_m`, so it tiles exactly.
class CobblestoneTexture : public Texture {
 public:
  explicit CobblestoneTexture(const core::ConfigSection& e)
      : Texture("cobblestone"),
        period_(positive(e, "period_m", 0.4)),
        gap_(positive(e, "gap_m", 0.008)),
        stone_(readColour(e, "colour", {140, 135, 128})),
        gap_colour_(readColour(e, "gap_colour", {60, 55, 50})),
        seed_(seedOf(e)) {
    int stones = 7;
    e.read("stones_per_period", stones);
    if (stones < 1)
      throw core::ConfigError(
          fmt::format("{}: {}.stones_per_period must be >= 1", e.origin(), e.path()));
    std::mt19937 rng(seed_);
    std::uniform_real_distribution<double> u(0.0, period_);
    for (int k = 0; k < stones; ++k) centres_.emplace_back(u(rng), u(rng));
  }

  cv::Vec3f colour(double s, double t) const override {
    const Eigen::Vector2d p(s - period_ * std::floor(s / period_),
                            t - period_ * std::floor(t / period_));
    double d1 = 1e9, d2 = 1e9;
    std::size_t nearest = 0;
    for (std::size_t k = 0; k < centres_.size(); ++k) {
      for (int dx = -1; dx <= 1; ++dx) {
        for (int dy = -1; dy <= 1; ++dy) {
          const double d = (p - centres_[k] - Eigen::Vector2d(dx * period_, dy * period_)).norm();
          if (d < d1) {
            d2 = d1, d1 = d, nearest = k;
          } else if (d < d2) {
            d2 = d;
          }
        }
      }
    }
    // The bisector between the two nearest centres is where (d2 - d1) / 2 vanishes.
    if ((d2 - d1) / 2 < gap_ / 2) return gap_colour_;
    const auto key = seed_ + static_cast<std::uint32_t>(nearest) * 977u;
    const double tone = 0.75 + 0.5 * noise::unit(static_cast<std::int64_t>(nearest), 1, seed_);
    return scaled(stone_, tone * (0.9 + 0.2 * noise::fractal(p.x() / 0.01, p.y() / 0.01, key, 3)));
  }

  std::optional<Lattice> lattice() const override {
    return Lattice{Eigen::Vector2d(period_, 0.0), Eigen::Vector2d(0.0, period_)};
  }

 private:
  double period_, gap_;
  cv::Vec3f stone_, gap_colour_;
  std::uint32_t seed_;
  std::vector<Eigen::Vector2d> centres_;
};

// Shapes drawn on a finite sheet (posters, blackboards): rectangles, discs and strokes.
class SheetTexture : public Texture {
 public:
  SheetTexture(const core::ConfigSection& e, std::string generator, bool chalk)
      : Texture(std::move(generator)),
        width_(positive(e, "width_m", chalk ? 1.8 : 0.6)),
        height_(positive(e, "height_m", chalk ? 1.0 : 0.85)),
        background_(
            readColour(e, "colour", chalk ? cv::Vec3f{38, 62, 50} : cv::Vec3f{235, 230, 215})),
        seed_(seedOf(e)),
        chalk_(chalk) {
    std::mt19937 rng(seed_);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    const int count = chalk ? 40 : 18;
    for (int k = 0; k < count; ++k) {
      Shape shape;
      shape.kind = chalk ? 2 : static_cast<int>(u(rng) * 3);
      shape.a = {u(rng) * width_, u(rng) * height_};
      shape.b =
          shape.a + Eigen::Vector2d((u(rng) - 0.5) * width_ * 0.5, (u(rng) - 0.5) * height_ * 0.5);
      shape.size = chalk ? 0.004 + 0.004 * u(rng) : 0.02 + 0.15 * u(rng);
      shape.colour =
          chalk ? cv::Vec3f(230, 230, 225) * static_cast<float>(0.8 + 0.2 * u(rng))
                : cv::Vec3f(static_cast<float>(255 * u(rng)), static_cast<float>(255 * u(rng)),
                            static_cast<float>(255 * u(rng)));
      shapes_.push_back(shape);
    }
  }

  cv::Vec3f colour(double s, double t) const override {
    const Eigen::Vector2d p(std::clamp(s, 0.0, width_), std::clamp(t, 0.0, height_));
    const double border = chalk_ ? 0.03 : 0.0;
    if (chalk_ &&
        (p.x() < border || p.y() < border || p.x() > width_ - border || p.y() > height_ - border)) {
      return scaled(cv::Vec3f(150, 105, 60),
                    0.9 + 0.2 * noise::value(p.x() / 0.01, p.y() / 0.002, seed_));
    }
    cv::Vec3f c =
        scaled(background_, 0.94 + 0.12 * noise::fractal(p.x() / 0.02, p.y() / 0.02, seed_, 3));
    for (const Shape& shape : shapes_) {
      if (shape.contains(p)) c = shape.colour;
    }
    return c;
  }

  std::optional<Eigen::Vector2d> extent() const override {
    return Eigen::Vector2d(width_, height_);
  }

 private:
  struct Shape {
    int kind = 0;  // 0 rectangle a..b, 1 disc at a of radius size, 2 stroke a-b of width size
    Eigen::Vector2d a, b;
    double size = 0.0;
    cv::Vec3f colour;
    bool contains(const Eigen::Vector2d& p) const {
      if (kind == 0) {
        const Eigen::Vector2d lo = a.cwiseMin(b), hi = a.cwiseMax(b);
        return (p.array() >= lo.array()).all() && (p.array() <= hi.array()).all();
      }
      if (kind == 1) return (p - a).norm() < size;
      const Eigen::Vector2d ab = b - a;
      const double h = std::clamp((p - a).dot(ab) / std::max(ab.squaredNorm(), 1e-12), 0.0, 1.0);
      return (p - a - h * ab).norm() < size / 2;
    }
  };
  double width_, height_;
  cv::Vec3f background_;
  std::uint32_t seed_;
  bool chalk_;
  std::vector<Shape> shapes_;
};

// Unique, non-periodic surfaces: plaster (fractal noise) and wood (wavy grain).
class NoiseTexture : public Texture {
 public:
  NoiseTexture(const core::ConfigSection& e, std::string generator, bool wood)
      : Texture(std::move(generator)),
        base_(readColour(e, "colour", wood ? cv::Vec3f{150, 100, 60} : cv::Vec3f{228, 224, 214})),
        seed_(seedOf(e)),
        wood_(wood) {}

  cv::Vec3f colour(double s, double t) const override {
    if (!wood_) return scaled(base_, 0.9 + 0.2 * noise::fractal(s / 0.05, t / 0.05, seed_, 5));
    const double warp = noise::fractal(s / 0.2, t / 0.03, seed_, 4);
    const double ring = 0.5 + 0.5 * std::sin(t / 0.004 + 12.0 * warp);
    return scaled(base_, 0.75 + 0.3 * ring + 0.1 * noise::value(s / 0.002, t / 0.01, seed_ + 3));
  }

 private:
  cv::Vec3f base_;
  std::uint32_t seed_;
  bool wood_;
};

// A photograph or tile image, `width_m` wide; repeated when `tile: true`.
class ImageTexture : public Texture {
 public:
  ImageTexture(const core::ConfigSection& e, const std::string& scene_dir) : Texture("image") {
    std::string path;
    e.read("image", path);
    if (path.empty()) {
      throw core::ConfigError(fmt::format("{}: {} needs 'image: FILE'", e.origin(), e.path()));
    }
    std::filesystem::path file(path);
    if (file.is_relative()) file = std::filesystem::path(scene_dir) / file;
    cv::Mat bgr = cv::imread(file.string(), cv::IMREAD_COLOR);
    if (bgr.empty()) {
      throw core::ConfigError(fmt::format("{}: {}: image {} is missing or unreadable", e.origin(),
                                          e.path(), file.string()));
    }
    cv::cvtColor(bgr, image_, cv::COLOR_BGR2RGB);
    image_.convertTo(image_, CV_32FC3);
    width_ = positive(e, "width_m", 1.0);
    height_ = width_ * image_.rows / image_.cols;
    e.read("tile", tile_);
  }

  cv::Vec3f colour(double s, double t) const override {
    double x = s / width_ * image_.cols - 0.5, y = t / height_ * image_.rows - 0.5;
    const auto fetch = [&](int u, int v) {
      if (tile_) {
        u = static_cast<int>(wrap(u, image_.cols));
        v = static_cast<int>(wrap(v, image_.rows));
      } else {
        u = std::clamp(u, 0, image_.cols - 1);
        v = std::clamp(v, 0, image_.rows - 1);
      }
      // Row 0 of the image is the top of the picture: t grows upwards.
      return image_.at<cv::Vec3f>(image_.rows - 1 - v, u);
    };
    const double fx = std::floor(x), fy = std::floor(y);
    const auto u = static_cast<int>(fx), v = static_cast<int>(fy);
    const auto ax = static_cast<float>(x - fx), ay = static_cast<float>(y - fy);
    return (fetch(u, v) * (1 - ax) + fetch(u + 1, v) * ax) * (1 - ay) +
           (fetch(u, v + 1) * (1 - ax) + fetch(u + 1, v + 1) * ax) * ay;
  }

  std::optional<Lattice> lattice() const override {
    if (!tile_) return std::nullopt;
    return Lattice{Eigen::Vector2d(width_, 0.0), Eigen::Vector2d(0.0, height_)};
  }
  std::optional<Eigen::Vector2d> extent() const override {
    if (tile_) return std::nullopt;
    return Eigen::Vector2d(width_, height_);
  }

 private:
  cv::Mat image_;
  double width_ = 1.0, height_ = 1.0;
  bool tile_ = false;
};

using Factory =
    std::function<std::unique_ptr<Texture>(const core::ConfigSection&, const std::string&)>;

const std::map<std::string, Factory>& registry() {
  static const std::map<std::string, Factory> factories = {
      {"brick", [](const auto& e, const auto&) { return std::make_unique<BrickTexture>(e); }},
      {"tiles", [](const auto& e, const auto&) { return std::make_unique<TileTexture>(e); }},
      {"cobblestone",
       [](const auto& e, const auto&) { return std::make_unique<CobblestoneTexture>(e); }},
      {"poster", [](const auto& e,
                    const auto&) { return std::make_unique<SheetTexture>(e, "poster", false); }},
      {"blackboard",
       [](const auto& e, const auto&) {
         return std::make_unique<SheetTexture>(e, "blackboard", true);
       }},
      {"plaster", [](const auto& e,
                     const auto&) { return std::make_unique<NoiseTexture>(e, "plaster", false); }},
      {"wood",
       [](const auto& e, const auto&) { return std::make_unique<NoiseTexture>(e, "wood", true); }},
      {"image",
       [](const auto& e, const auto& dir) { return std::make_unique<ImageTexture>(e, dir); }},
  };
  return factories;
}

}  // namespace

std::vector<std::string> textureGenerators() {
  std::vector<std::string> names;
  for (const auto& [name, factory] : registry()) names.push_back(name);
  return names;
}

std::unique_ptr<Texture> makeTexture(const core::ConfigSection& entry,
                                     const std::string& scene_dir) {
  std::string generator;
  entry.read("generator", generator);
  const auto found = registry().find(generator);
  if (found == registry().end()) {
    throw core::ConfigError(fmt::format("{}: {}: unknown texture generator '{}' (known: {})",
                                        entry.origin(), entry.path(), generator,
                                        fmt::join(textureGenerators(), ", ")));
  }
  return found->second(entry, scene_dir);
}

}  // namespace tessera::drivers::synthetic
