// Draws a run's finalized patch outlines over one of its frames, to look at what was found.
//
//   patch_overlay RUN_DIR SOURCE [--frame N] [--out FILE.png]
//
// RUN_DIR is the output of `tessera run SOURCE --out RUN_DIR` (patches.json, trajectory.txt);
// the frame is drawn at the pose it was fused at. Each patch gets its own colour, a
// translucent fill of its outline (holes left clear) and its id.
#include <fstream>

#include <fmt/format.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "bench_frames.h"
#include "tessera/core/error.h"
#include "tessera/core/intrinsics.h"
#include "tessera/core/log.h"
#include "tessera/core/trajectory.h"

namespace {

using tessera::core::Error;

Eigen::Vector3d vec3(const nlohmann::json& j) {
  return {j.at(0).get<double>(), j.at(1).get<double>(), j.at(2).get<double>()};
}

// The polygon's edges sampled every 1 cm, projected; points behind the camera are dropped.
std::vector<cv::Point> project(const nlohmann::json& polygon, const Eigen::Vector3d& origin,
                               const Eigen::Vector3d& u, const Eigen::Vector3d& v,
                               const tessera::core::Isometry& T_C_W,
                               const tessera::core::Intrinsics& k) {
  std::vector<cv::Point> pixels;
  const std::size_t n = polygon.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d a(polygon[i][0].get<double>(), polygon[i][1].get<double>());
    const Eigen::Vector2d b(polygon[(i + 1) % n][0].get<double>(),
                            polygon[(i + 1) % n][1].get<double>());
    const int steps = std::max(1, static_cast<int>((b - a).norm() / 0.01));
    for (int s = 0; s < steps; ++s) {
      const Eigen::Vector2d p = a + (b - a) * (static_cast<double>(s) / steps);
      const Eigen::Vector3d X = T_C_W * (origin + p.x() * u + p.y() * v);
      if (X.z() < 0.1) continue;
      pixels.emplace_back(static_cast<int>(k.fx * X.x() / X.z() + k.cx),
                          static_cast<int>(k.fy * X.y() / X.z() + k.cy));
    }
  }
  return pixels;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Draw a run's patch outlines over one of its frames"};
  std::string run_dir, source_path, out_path = "patch_overlay.png";
  std::size_t frame_index = 0;
  app.add_option("RUN_DIR", run_dir, "Output folder of tessera run")->required();
  app.add_option("SOURCE", source_path, "The recording or dataset folder of that run")->required();
  app.add_option("--frame", frame_index, "Index of the frame to draw on");
  app.add_option("--out", out_path, "PNG to write");
  std::string intrinsics_spec;
  app.add_option("--intrinsics", intrinsics_spec,
                 "Camera intrinsics 'fx,fy,cx,cy[,width,height]' when the source has none");
  CLI11_PARSE(app, argc, argv);
  tessera::core::initLogging("warn");
  try {
    std::optional<tessera::core::Intrinsics> intrinsics;
    if (!intrinsics_spec.empty()) intrinsics = tessera::core::parseIntrinsicsSpec(intrinsics_spec);
    const auto frames =
        tessera::bench::loadFrames(source_path, frame_index + 1, false, intrinsics);
    if (frames.size() <= frame_index) {
      throw Error(fmt::format("{}: has only {} frames", source_path, frames.size()));
    }
    const tessera::core::Frame& frame = frames[frame_index];
    const auto trajectory = tessera::core::readTumTrajectory(run_dir + "/trajectory.txt");
    // trajectory.txt keeps timestamps to the microsecond: take the pose nearest in time.
    auto pose = trajectory.lower_bound(frame.timestamp_ns - 1000);
    if (pose != trajectory.end() && std::abs(pose->first - frame.timestamp_ns) > 1000) {
      pose = trajectory.end();
    }
    if (pose == trajectory.end()) {
      throw Error(fmt::format("{}/trajectory.txt: frame {} was not fused", run_dir, frame_index));
    }
    const tessera::core::Isometry T_C_W = pose->second.inverse();
    std::ifstream in(run_dir + "/patches.json");
    if (!in) throw Error(run_dir + "/patches.json: cannot open");
    const nlohmann::json patches = nlohmann::json::parse(in);

    cv::Mat image;
    cv::cvtColor(frame.rgb, image, cv::COLOR_RGB2BGR);
    cv::Mat fill = image.clone();
    const cv::Scalar palette[] = {{0, 0, 255},   {0, 200, 0},   {255, 0, 0},   {0, 200, 255},
                                  {255, 0, 255}, {255, 255, 0}, {0, 128, 255}, {128, 0, 255}};
    struct Outline {
      int id;
      cv::Scalar colour;
      std::vector<std::vector<cv::Point>> rings;
    };
    std::vector<Outline> outlines;
    int drawn = 0;
    for (const auto& patch : patches.at("patches")) {
      const int id = patch.at("id").get<int>();
      const cv::Scalar colour = palette[static_cast<std::size_t>(id) % std::size(palette)];
      const Eigen::Vector3d origin = vec3(patch.at("origin")), u = vec3(patch.at("u_axis")),
                            v = vec3(patch.at("v_axis"));
      for (const auto& part : patch.at("outline")) {
        const auto outer = project(part.at("outer"), origin, u, v, T_C_W, frame.intrinsics);
        if (outer.size() < 3) continue;
        std::vector<std::vector<cv::Point>> rings{outer};
        for (const auto& hole : part.at("holes")) {
          rings.push_back(project(hole, origin, u, v, T_C_W, frame.intrinsics));
        }
        cv::fillPoly(fill, rings, colour);  // even-odd: holes stay clear
        outlines.push_back({id, colour, rings});
        ++drawn;
      }
    }
    cv::addWeighted(fill, 0.35, image, 0.65, 0.0, image);
    for (const Outline& outline : outlines) {
      cv::polylines(image, outline.rings, true, outline.colour, 2);
      const cv::Moments m = cv::moments(outline.rings.front());
      if (m.m00 != 0.0) {
        cv::putText(image, std::to_string(outline.id),
                    cv::Point(static_cast<int>(m.m10 / m.m00), static_cast<int>(m.m01 / m.m00)),
                    cv::FONT_HERSHEY_SIMPLEX, 0.8, outline.colour, 2);
      }
    }
    if (!cv::imwrite(out_path, image)) throw Error(out_path + ": cannot write");
    fmt::print("{}: {} outline parts of {} patches over frame {}\n", out_path, drawn,
               patches.at("patches").size(), frame_index);
    return 0;
  } catch (const std::exception& e) {
    fmt::print(stderr, "patch_overlay: {}\n", e.what());
    return 1;
  }
}
