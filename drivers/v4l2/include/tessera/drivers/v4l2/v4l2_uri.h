#pragma once
// The source URI of a V4L2 camera.
//
//   v4l2://[COLOUR_NODE]?depth=DEPTH_NODE[&profile=kinect_v2][&calibration=FILE.yaml]
//
//   v4l2:///dev/video0?depth=/dev/video2                    colour /dev/video0, depth /dev/video2
//   v4l2://?depth=/dev/video2                               depth only (no colour node)
//   v4l2:///dev/video0?depth=/dev/video2&profile=kinect_v2  Kinect v2 sizes and calibration
//
// The colour node is the URI's path, so it needs the third slash; the depth node is always the
// `depth` query key, because tessera cannot fuse without depth. Node paths are absolute
// (/dev/videoN or a stable /dev/v4l/by-id/... link) and taken verbatim (no %-decoding).
// `calibration` names a YAML file (see config/kinect_v2.yaml) and overrides the profile's.
#include <string>
#include <vector>

namespace tessera::drivers::v4l2 {

struct V4l2Uri {
  std::string colour_path;  // empty: depth only
  std::string depth_path;
  std::string profile;      // empty or one of knownV4l2Profiles()
  std::string calibration;  // empty: the profile's file (or, without a profile, none)
};

// True when `spec` is meant as a V4L2 URI (starts with "v4l2:"), well-formed or not.
bool isV4l2Uri(const std::string& spec);

// Throws core::ConfigError naming the URI and what is wrong: another scheme, a relative node
// path, a missing depth node, an unknown or repeated key, an unknown profile, the same node for
// depth and colour.
V4l2Uri parseV4l2Uri(const std::string& uri);

const std::vector<std::string>& knownV4l2Profiles();  // {"kinect_v2"}

}  // namespace tessera::drivers::v4l2
