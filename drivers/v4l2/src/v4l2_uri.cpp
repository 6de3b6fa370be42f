#include "tessera/drivers/v4l2/v4l2_uri.h"

#include <algorithm>
#include <string_view>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "tessera/core/error.h"

namespace tessera::drivers::v4l2 {

namespace {

constexpr std::string_view kScheme = "v4l2://";
constexpr const char* kExample = "v4l2:///dev/video0?depth=/dev/video2";

std::vector<std::string_view> split(std::string_view text, char separator) {
  std::vector<std::string_view> parts;
  std::size_t start = 0;
  for (;;) {
    const std::size_t at = text.find(separator, start);
    parts.push_back(text.substr(start, at - start));
    if (at == std::string_view::npos) return parts;
    start = at + 1;
  }
}

}  // namespace

const std::vector<std::string>& knownV4l2Profiles() {
  static const std::vector<std::string> profiles{"kinect_v2"};
  return profiles;
}

bool isV4l2Uri(const std::string& spec) { return spec.rfind("v4l2:", 0) == 0; }

V4l2Uri parseV4l2Uri(const std::string& uri) {
  const auto fail = [&uri](const std::string& what) {
    return core::ConfigError(fmt::format("'{}': {}", uri, what));
  };
  if (uri.rfind(kScheme, 0) != 0) {
    throw fail(fmt::format("a V4L2 source starts with v4l2://, e.g. {}", kExample));
  }
  const std::string_view rest = std::string_view(uri).substr(kScheme.size());
  const std::size_t question = rest.find('?');
  V4l2Uri parsed;
  parsed.colour_path = std::string(rest.substr(0, question));
  if (!parsed.colour_path.empty() && parsed.colour_path.front() != '/') {
    throw fail(
        fmt::format("the colour node '{}' is not an absolute path (mind the third slash: {})",
                    parsed.colour_path, kExample));
  }

  std::vector<std::string> seen;
  const std::string_view query =
      question == std::string_view::npos ? std::string_view() : rest.substr(question + 1);
  for (const std::string_view item :
       query.empty() ? std::vector<std::string_view>() : split(query, '&')) {
    const std::size_t equals = item.find('=');
    if (equals == std::string_view::npos || equals == 0 || equals + 1 == item.size()) {
      throw fail(fmt::format("query item '{}' is not key=value", item));
    }
    const std::string key(item.substr(0, equals));
    const std::string value(item.substr(equals + 1));
    if (std::find(seen.begin(), seen.end(), key) != seen.end()) {
      throw fail(fmt::format("key '{}' is given twice", key));
    }
    seen.push_back(key);
    if (key == "depth") {
      parsed.depth_path = value;
    } else if (key == "profile") {
      parsed.profile = value;
    } else if (key == "calibration") {
      parsed.calibration = value;
    } else {
      throw fail(fmt::format("unknown key '{}'; the keys are depth, profile, calibration", key));
    }
  }

  if (parsed.depth_path.empty()) {
    throw fail(fmt::format(
        "no depth node; add ?depth=/dev/videoN (colour goes in the path, empty for depth only: "
        "v4l2://?depth=/dev/video2)"));
  }
  if (parsed.depth_path.front() != '/') {
    throw fail(fmt::format("the depth node '{}' is not an absolute path", parsed.depth_path));
  }
  if (parsed.depth_path == parsed.colour_path) {
    throw fail("depth and colour are the same node; a V4L2 node streams one format at a time");
  }
  const auto& profiles = knownV4l2Profiles();
  if (!parsed.profile.empty() &&
      std::find(profiles.begin(), profiles.end(), parsed.profile) == profiles.end()) {
    throw fail(fmt::format("unknown profile '{}'; the profiles are {}", parsed.profile,
                           fmt::join(profiles, ", ")));
  }
  return parsed;
}

}  // namespace tessera::drivers::v4l2
