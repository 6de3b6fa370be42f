#include "tessera/core/intrinsics.h"

#include <cmath>
#include <sstream>
#include <vector>

#include <fmt/format.h>

#include "tessera/core/config.h"
#include "tessera/core/error.h"

namespace tessera::core {

bool Intrinsics::valid() const {
  return width > 0 && height > 0 && std::isfinite(fx) && std::isfinite(fy) && fx != 0.0 &&
         fy != 0.0 && std::isfinite(cx) && std::isfinite(cy);
}

std::string Intrinsics::describe() const {
  return fmt::format("fx={} fy={} cx={} cy={} ({}x{})", fx, fy, cx, cy, width, height);
}

Intrinsics loadIntrinsicsYaml(const std::filesystem::path& path) {
  const ConfigDocument doc = ConfigDocument::load(path);
  Intrinsics k;
  const ConfigSection root = doc.root();
  root.read("fx", k.fx);
  root.read("fy", k.fy);
  root.read("cx", k.cx);
  root.read("cy", k.cy);
  root.read("width", k.width);
  root.read("height", k.height);
  doc.checkAllKeysUsed();
  for (const char* key : {"fx", "fy", "cx", "cy"}) {
    for (const std::string& absent : doc.keysAskedButAbsent()) {
      if (absent == key) {
        throw ConfigError(fmt::format("{}: intrinsics key '{}' is missing", path.string(), key));
      }
    }
  }
  if (k.fx == 0.0 || k.fy == 0.0) {
    throw ConfigError(fmt::format("{}: focal lengths must be non-zero", path.string()));
  }
  return k;
}

Intrinsics parseIntrinsicsSpec(const std::string& spec) {
  const bool looks_numeric =
      !spec.empty() && spec.find_first_not_of("0123456789.,-+eE ") == std::string::npos;
  if (!looks_numeric) return loadIntrinsicsYaml(spec);

  std::vector<double> values;
  std::stringstream stream(spec);
  std::string item;
  while (std::getline(stream, item, ',')) {
    try {
      std::size_t used = 0;
      values.push_back(std::stod(item, &used));
      if (item.find_first_not_of(' ', used) != std::string::npos) throw std::invalid_argument("");
    } catch (const std::exception&) {
      throw ConfigError(fmt::format("--intrinsics '{}': '{}' is not a number", spec, item));
    }
  }
  if (values.size() != 4 && values.size() != 6) {
    throw ConfigError(
        fmt::format("--intrinsics '{}': expected fx,fy,cx,cy or fx,fy,cx,cy,width,height", spec));
  }
  Intrinsics k;
  k.fx = values[0];
  k.fy = values[1];
  k.cx = values[2];
  k.cy = values[3];
  if (values.size() == 6) {
    k.width = static_cast<int>(values[4]);
    k.height = static_cast<int>(values[5]);
  }
  if (k.fx == 0.0 || k.fy == 0.0) {
    throw ConfigError(fmt::format("--intrinsics '{}': focal lengths must be non-zero", spec));
  }
  return k;
}

}  // namespace tessera::core
