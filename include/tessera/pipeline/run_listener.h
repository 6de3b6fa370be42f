#pragma once
// What a run tells those who follow it from outside the process (the ROS publisher): each
// frame's pose, each committed patch with its coloured surface, each retired patch, and the
// files the map was exported to. Calls come from the pipeline's serial nodes (poses in stream
// order, patches in finalization order): an implementation copies what it needs and returns.
#include <cstdint>
#include <filesystem>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "tessera/core/pose.h"
#include "tessera/planes/patch_map.h"
#include "tessera/texture/texel_grid.h"

namespace tessera::pipeline {

// A finalized patch as the map shows it: its bitmap laid on its plane in the world.
struct PatchSurface {
  int id = 0, version = 0;
  bool reused = false;                       // its texture was stored before
  planes::Patch::Frame plane;                // the plane's (u, v) axes in the world
  const texture::TexelGrid* grid = nullptr;  // texel (col, row) -> (u, v); its mask
  const cv::Mat* image = nullptr;            // CV_8UC3 RGB, grid.height x grid.width
};

class RunListener {
 public:
  virtual ~RunListener() = default;
  // The map's pose of a frame (tracked, corrected against the planes), at its capture time;
  // none for a frame without pose or held apart (FusedFrame::held_apart).
  virtual void onPose(std::int64_t timestamp_ns, const core::Isometry& T_W_C) = 0;
  virtual void onPatch(const PatchSurface& patch) = 0;
  // The patch was merged into another: it leaves the map.
  virtual void onPatchRetired(int patch_id) = 0;
  // The run is over and its map written to these files.
  virtual void onExported(const std::vector<std::filesystem::path>& files) = 0;
};

}  // namespace tessera::pipeline
