#pragma once
// Pinhole intrinsics of the depth camera (colour is registered to depth).
#include <filesystem>
#include <string>

namespace tessera::core {

struct Intrinsics {
  int width = 0;   // pixels
  int height = 0;  // pixels
  double fx = 0.0;
  double fy = 0.0;  // may be negative (ICL-NUIM convention: image y axis flipped)
  double cx = 0.0;
  double cy = 0.0;

  // True when the focal lengths are non-zero and the size is known.
  bool valid() const;
  std::string describe() const;
};

// Parses a --intrinsics value: either "fx,fy,cx,cy" (optionally followed by ",width,height")
// or the path of a YAML file with keys fx, fy, cx, cy and optional width, height.
// Throws ConfigError naming the value or file on anything malformed.
Intrinsics parseIntrinsicsSpec(const std::string& spec);

// Reads a YAML intrinsics file (keys as above). Throws ConfigError.
Intrinsics loadIntrinsicsYaml(const std::filesystem::path& path);

}  // namespace tessera::core
