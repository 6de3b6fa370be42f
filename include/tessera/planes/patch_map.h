#pragma once
// The global set of planar patches: detected regions are associated with the patches they
// continue (same plane within bounds, and touching what the patch already covers), patches
// found to be one plane are merged, and each patch's plane is refitted from all its points.
// Each patch collects colour samples from the raw frames and is finalized once it stops
// growing or leaves the view; a finalized patch that grows again is finalized anew as a
// higher version of the same id. A plane larger than one tile (PatchMapConfig::tile_m) is cut
// into tiles on a grid of its plane, each one a patch of its own: a growing floor re-textures
// the tile that grows, not the whole building. A Plane (plane.h) owns its geometry, points,
// tile grid and observers; a tile (Patch) owns its cells, colour samples and lifecycle.
#include <array>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <functional>
#include <iterator>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "tessera/core/frame.h"
#include "tessera/core/pose.h"
#include "tessera/planes/colour_samples.h"
#include "tessera/planes/patch_outline.h"
#include "tessera/planes/plane.h"
#include "tessera/planes/plane_detector.h"
#include "tessera/planes/plane_fit.h"

namespace tessera::planes {

struct PatchMapConfig {
  double max_normal_angle_deg = 5.0;  // a region continues a patch only this close in normal
  // A region's pixels also colour the growing tiles of planes this close to its own (normal,
  // and offset at its plane's origin) where their depth confirms them (0: never).
  double colour_neighbour_angle_deg = 15.0;
  double colour_neighbour_offset_m = 0.10;
  double max_offset_m = 0.03;         // ... and with its centroid this close to its plane
  // After a loop closure, a plane merges into an older one it continues. One fit cannot follow
  // a floor that tracking drift bent over metres, so there the offset bound grows by
  // tan(merge_bend_deg) per metre from the older plane's centroid.
  double merge_bend_deg = 0.3;
  // After a loop closure, the cells and colours of each 10 cm block also move within the plane
  // by their own keyframes' correction (Plane::blocks), not only with the plane as a whole.
  bool move_within_plane = true;
  // A tile moves once some block of it is owed this much; smaller moves wait (and add up), so
  // that each small correction does not texture the plane again.
  double min_move_within_plane_m = 0.01;
  // A tile moved within its plane is finalized again (textured anew) no sooner than this many
  // frames after its last move: the optimisations of loop closures come in bursts.
  int moved_settle_frames = 300;
  // A correction's moves within planes are made plane by plane (a plane's due tiles all at
  // once) until at least this many tiles have moved in a frame (0: all at once); the rest
  // follow over the next frames (moveWithinPlanes), so that no frame waits on all of them.
  int max_tiles_moved_per_frame = 2;
  double cell_m = 0.05;               // occupancy grid cell in the plane
  // Finalization: a patch in view is stable once its area grew by at most max_growth (a
  // fraction) over its last stable_frames frames in view; a patch not seen for
  // out_of_view_frames frames is finalized as it is. Patches under min_area_m2 never are.
  int stable_frames = 30;
  double max_growth = 0.02;
  int out_of_view_frames = 60;
  double min_area_m2 = 0.1;
  // A finalized patch unseen for this many frames moves its colour samples out of memory into
  // a file (PatchMap::setSampleSpillDir), and loads them back if it is seen again; 0 keeps
  // them. Its texture was made from them at finalization: memory stays bounded on long runs.
  int release_samples_after_frames = 90;
  // A plane that outgrows tile_m along its u or v axis is cut into tile_m x tile_m tiles, each
  // a patch with its own id, samples, texture and versions, sharing the plane. Surfaces up to
  // tile_m are never cut. 0 never cuts.
  double tile_m = 6.0;
  // Colour samples: each sample_cell_m square of the plane blends the samples that fall in it.
  // With sample_views > 0 it blends those of one view only, and each 32 x 32 cells keep the
  // sample_views views of most summed weight apart, for view selection.
  double sample_cell_m = 0.0035;
  int sample_views = 0;
  // Colours are taken from every N-th frame (and from frames far from the last one sampled):
  // at 30 frames/s neighbouring frames see nearly the same thing, and sampling is the
  // costliest part of the plane stage.
  int colour_every_n_frames = 2;
  // Colour placed with the camera's pose at the colour image's own time stamp, where the source
  // gives one (a Kinect v1 does not synchronise its two cameras: on TUM the colour is 9.5 ms
  // from the depth on average), from the camera's motion between frames.
  bool colour_at_colour_time = true;
  // A pixel colours its patch only where the measured depth agrees with the patch's plane
  // within colour_depth_tolerance_m + colour_depth_tolerance_per_m2 * z^2 (the sensor's noise
  // grows with z^2): what stands on or in front of the plane (clutter, an occluder) is not its
  // texture. Pixels within colour_edge_margin_px of a pixel that fails this test (a depth
  // discontinuity, where colour and depth disagree most) are left out too.
  double colour_depth_tolerance_m = 0.01;
  double colour_depth_tolerance_per_m2 = 0.005;
  int colour_edge_margin_px = 2;
  // Per-frame gain per channel, estimated against what the patches already hold and applied
  // before blending (planes/exposure.h); the bitmap is brought back to the mean exposure of
  // the frames that coloured it. Off by default: it makes a uniform surface uniform, but each
  // real view keeps its own exposure, and the per-cell mean of the views that saw a cell fits
  // them better (measured in docs/MEASUREMENTS.md, "Textures on real cameras").
  bool exposure_compensation = false;
};

// One detected region in world coordinates.
struct PlaneObservation {
  std::vector<Eigen::Vector3d> points_W;
  // Where the camera was: a new patch's normal points away from it, into the surface, so that
  // its (u, v) frame and every bitmap on it show the surface as seen from the front, never
  // mirrored (a texture seen twice, or imported from a photo, then matches by a similarity).
  Eigen::Vector3d camera_W = Eigen::Vector3d::Zero();
  // With loop closure: the time of the keyframe the frame was tracked after, and the
  // loop-closure motion its points were moved by (identity before any loop); the plane they go
  // to follows later corrections of that keyframe (followCorrection). Without a keyframe the
  // plane does not record them (its record grows by one entry per keyframe that saw it).
  std::optional<std::int64_t> keyframe_ns;
  core::Isometry loop_motion = core::Isometry::Identity();
};

// The regions of `detection` as world points (frame seen from T_W_C).
std::vector<PlaneObservation> observationsOf(const core::Frame& frame,
                                             const PlaneDetection& detection,
                                             const core::Isometry& T_W_C);

// One tile of a plane (the whole plane, if it is not cut): its cells, colours and lifecycle.
struct Patch {
  int id = 0;
  int plane = 0;    // its plane's id (Plane::id)
  Cell tile{0, 0};  // the tile's key in its plane's TileGrid
  // The plane's geometry, as the plane keeps it (shared, read only here).
  std::shared_ptr<const PlaneGeometry> geometry = std::make_shared<const PlaneGeometry>();
  CellSet cells;
  // Shared with its snapshots while they are textured (SharedColourSamples::edit to change);
  // PatchMap sets its configured cell.
  SharedColourSamples samples{ColourSamples(PatchMapConfig{}.sample_cell_m)};
  // Sum over every coloured pixel of its footprint on the plane (distance / fx, metres), for
  // the texel size that matches how sharply the sensor saw the patch.
  double footprint_sum_m = 0.0;
  std::size_t footprint_pixels = 0;
  // Sum over every coloured pixel of the log gain its frame was compensated by, per channel:
  // the patch's texture is brought back to the mean exposure of its views.
  Eigen::Vector3d log_gain_sum = Eigen::Vector3d::Zero();

  // Where the samples are while they are out of memory (PatchMapConfig::
  // release_samples_after_frames); `samples` is then empty.
  std::optional<std::filesystem::path> spilled_samples;

  // Finalization state.
  int version = 0;  // 0: never finalized; each finalization adds one
  bool finalized = false;
  double finalized_area_m2 = 0.0;
  std::deque<double> area_in_view;  // area after each of the last frames the patch was seen in
  long last_seen_frame = -1;
  int frames_seen = 0;
  // Frames to wait before finalizing again after its content moved within its plane
  // (PatchMapConfig::moved_settle_frames).
  int frames_to_settle = 0;

  // The plane's, for the tile's users.
  const Eigen::Vector3d& normal() const { return geometry->normal; }
  double offset() const { return geometry->offset; }
  using Frame = PlaneGeometry::Frame;
  Frame planeFrame() const { return geometry->planeFrame(); }
  Cell cellOf(const Eigen::Vector3d& X_W, double cell_m) const {
    return geometry->cellOf(X_W, cell_m);
  }
  Eigen::Vector3d cellCentre(const Cell& cell, double cell_m) const {
    return geometry->cellCentre(cell, cell_m);
  }
};

// The tiles of a map in id order, as `const Patch&`.
class TileRange {
 public:
  using Map = std::map<int, Patch>;
  class Iterator {
   public:
    using iterator_category = std::forward_iterator_tag;
    using value_type = Patch;
    using difference_type = std::ptrdiff_t;
    using pointer = const Patch*;
    using reference = const Patch&;
    explicit Iterator(Map::const_iterator it) : it_(it) {}
    const Patch& operator*() const { return it_->second; }
    const Patch* operator->() const { return &it_->second; }
    Iterator& operator++() {
      ++it_;
      return *this;
    }
    bool operator==(const Iterator& other) const { return it_ == other.it_; }
    bool operator!=(const Iterator& other) const { return it_ != other.it_; }

   private:
    Map::const_iterator it_;
  };
  explicit TileRange(const Map& tiles) : tiles_(tiles) {}
  Iterator begin() const { return Iterator(tiles_.begin()); }
  Iterator end() const { return Iterator(tiles_.end()); }
  std::size_t size() const { return tiles_.size(); }
  bool empty() const { return tiles_.empty(); }
  const Patch& front() const { return tiles_.begin()->second; }
  // The i-th tile in id order (walks the map: for tests and small maps).
  const Patch& operator[](std::size_t i) const {
    return std::next(tiles_.begin(), static_cast<long>(i))->second;
  }

 private:
  const Map& tiles_;
};

// A finalized patch as the texturing stage needs it, copied so that it can be textured on
// another thread while the map goes on changing.
struct PatchSnapshot {
  int id = 0;
  int version = 0;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double offset = 0.0;
  Patch::Frame frame;
  Outline outline;
  // The samples, either listed here or, as the map gives them, its cells shared (read only)
  // and listed by sampleList on the thread that textures the patch, each colour times
  // `colour_scale` (the exposure the map compensated to, undone).
  std::vector<ColourSample> samples;
  std::shared_ptr<const ColourSamples> shared_samples;
  std::optional<Eigen::Vector3d> colour_scale;
  double pixel_footprint_m = 0.0;  // mean footprint of the pixels that coloured it (0: none)
};

// The snapshot's samples as a list (PatchSnapshot::samples).
std::vector<ColourSample> sampleList(const PatchSnapshot& patch);
// How many samples sampleList gives, without listing them.
std::size_t sampleCount(const PatchSnapshot& patch);

// What changed for downstream stages: a patch (re)finalized as `version`, or a patch that was
// finalized before and has since been merged into another (its id is gone).
struct PatchEvent {
  enum class Kind { kFinalized, kRetired };
  Kind kind;
  int id;
  int version;
  double area_m2 = 0.0;  // of the finalized version
  // Why a patch was finalized: "stable" (in view, stopped growing), "out of view" (unseen for
  // out_of_view_frames) or "end of stream"; empty for a retirement.
  const char* reason = "";
};

// The ids of the patches `events` finalizes, in their order.
std::vector<int> finalizedIds(const std::vector<PatchEvent>& events);

class PatchMap {
 public:
  explicit PatchMap(const PatchMapConfig& config) : config_(config) {}

  // Adds one frame's regions; returns, per region, the id of the patch it went to.
  std::vector<int> add(const std::vector<PlaneObservation>& observations);

  // Colours of the frame's pixels in the regions that went to patches `ids` (as add returned
  // them): each pixel's ray meets its patch's plane, weighted by |cos| of the viewing angle
  // over the squared distance, times `sharpness` (SharpnessGauge); only pixels whose measured
  // depth confirms the plane, away from depth discontinuities. With exposure compensation the
  // colours are first multiplied by the frame's gain. Needs rgb registered to depth. Returns
  // the gain applied (1 without compensation; the last frame's when this one overlaps too
  // little of what the patches hold to estimate its own), or nothing when no pixel gave colour.
  // T_W_C_colour: the camera's pose when the colour image was taken, where that differs from
  // the depth image's time (T_W_C): a pixel's depth is tested at T_W_C, its colour placed on
  // the plane along its ray at T_W_C_colour.
  std::optional<Eigen::Vector3f> addColours(
      const core::Frame& frame, const PlaneDetection& detection, const core::Isometry& T_W_C,
      const std::vector<int>& ids, double sharpness = 1.0,
      const std::optional<core::Isometry>& T_W_C_colour = std::nullopt);

  // Closes frame `frame_index` (patches seen in it are the ones add() touched since the last
  // call) and returns the finalizations and retirements it caused.
  std::vector<PatchEvent> endFrame(long frame_index);
  // Loop closure moved the keyframes: each keyframe's points on a plane should move by
  // motion_at(keyframe) * (the motion they were placed with)^-1. A plane stays a plane, so it
  // moves by the mean of its keyframes' moves, weighted by how many points each gave, about
  // its centroid; with move_within_plane each block's cells and samples then move within it by
  // the rest of their own keyframes' moves (moveWithinPlanes, which it starts). Returns how many
  // planes moved.
  std::size_t followCorrection(
      const std::function<core::Isometry(std::int64_t keyframe_ns)>& motion_at);
  // Moves the due tiles of the planes whose within-plane moves are still pending, plane by
  // plane, until max_tiles_moved_per_frame tiles have moved (at least one plane; 0: all).
  // followCorrection starts it; call it once a frame, before the frame's points, until no
  // move is pending. Returns how many tiles moved.
  std::size_t moveWithinPlanes();
  bool withinPlaneMovesPending() const { return !moving_planes_.empty(); }
  // Merges each plane into an older one it now continues (the association bounds, touching
  // its cells): a place mapped twice before the loop closed. The tiles that took cells or
  // colours grow a new version (finalized again once stable or out of view, from the merged
  // samples); the merged plane's finalized tiles are retired. Returns how many merged.
  std::size_t mergeCoinciding();

  // At the end of the stream: finalizes every patch not finalized, above the area bound.
  std::vector<PatchEvent> finalizeAll();

  // The folder released samples go to (created if missing); without one nothing is released.
  void setSampleSpillDir(std::filesystem::path dir);
  // Moves the samples of finalized patches unseen for release_samples_after_frames frames to
  // files; returns how many patches released theirs. A file that cannot be written (disk full)
  // leaves the samples in memory, with a warning.
  std::size_t releaseIdleSamples(long frame_index);
  std::size_t samplesReleased() const { return samples_released_; }
  // Tiles whose cells and samples moved within their plane after corrections, over the run.
  std::size_t tilesMovedWithinPlanes() const { return tiles_moved_within_planes_; }

  // The map for a later session to continue (`tessera run --continue`): planes, tiles, cells
  // and finalization state to `file`, each tile's colour samples to
  // samples_dir/patch_<id>.samples. Planes keep no record of this session's keyframes: the
  // next session's pose graph does not hold them. Throws core::Error naming a file that
  // cannot be written.
  void saveState(const std::filesystem::path& file, const std::filesystem::path& samples_dir) const;
  // Replaces the map with a saved one. Finalized patches' samples are linked into the spill
  // folder (set it first; without one they are read into memory) and read when their tile
  // grows again; growing patches' are read into memory.
  // Throws core::Error naming a missing, corrupt or newer file, or one saved with other cell
  // sizes; the map is unchanged then.
  void loadState(const std::filesystem::path& file, const std::filesystem::path& samples_dir);
  // Every plane so far is set aside: regions no longer continue it, nor does a plane merge
  // with it (a continued map the session could not find itself in: its frame is another).
  // Returns how many.
  std::size_t setAsideAll();
  // A loaded patch whose texture was not saved (a checkpoint taken before its commit) is
  // finalized again as soon as it is out of view, from its samples.
  void textureAgain(int id);

  const Patch* find(int id) const;
  // A copy of patch `id` for texturing (its outline traced, its samples shared with the map).
  PatchSnapshot snapshot(const Patch& patch) const;
  const PatchMapConfig& config() const { return config_; }
  // Whether a region (its least-squares plane and points, world frame) continues `patch`:
  // normal and centroid within the bounds, touching its cells (the tile's).
  // `extra_offset_m` widens the offset bound (a merge after loop closure).
  bool continues(const Patch& patch, const PlaneFit& region,
                 const std::vector<Eigen::Vector3d>& points, double extra_offset_m = 0.0) const;
  std::size_t liveCount() const;       // not finalized in their current state
  std::size_t finalizedCount() const;  // finalized, in their current version
  Outline outlineOf(const Patch& patch) const { return traceOutline(patch.cells, config_.cell_m); }

  TileRange patches() const { return TileRange(patches_); }
  const std::map<int, Plane>& planes() const { return planes_; }
  // Area covered by a patch's occupied cells, m^2.
  double areaM2(const Patch& patch) const;

 private:
  // Adds a region's points to plane `plane_id`, cutting new tiles as they are needed, and
  // counts them as the keyframe's in their blocks (Plane::blocks); returns the id of the tile
  // that got most of them.
  int placePoints(int plane_id, const std::vector<Eigen::Vector3d>& points,
                  const PointMoments& moments, std::optional<std::int64_t> keyframe_ns);
  // After plane `plane` moved by `plane_motion` (followCorrection): each block is owed, within
  // the plane, where its keyframes' own moves (`steps`, by keyframe time) take it, less where
  // the plane's move took it. Returns whether some tile is now due (moveDueTiles).
  bool oweWithinPlane(Plane& plane, const core::Isometry& plane_motion,
                      const std::map<std::int64_t, core::Isometry>& steps);
  // Moves the tiles of `plane` with a block owed at least min_move_within_plane_m (and every
  // tile such a block reaches): cells and samples by what their blocks are owed. Returns how
  // many tiles moved.
  std::size_t moveDueTiles(Plane& plane);
  // Makes the waiting moves of plane `plane_id`, if any (moveDueTiles); it waits no more.
  std::size_t finishMovesWithin(int plane_id);
  // Moves every tile of plane `from_id` (cells, samples) into plane `into_id`'s tiles; the
  // tiles moved are gone, and ids handed out for them become the tiles that took them.
  // Returns the ids of the tiles that took cells or samples.
  std::set<int> mergePlane(int into_id, int from_id, std::vector<int>& ids);
  // A plane (second) that continues an older one (first), if any.
  std::optional<std::pair<int, int>> findCoinciding() const;
  // Puts cells (in the plane's frame) into their tiles, which are created as needed and count
  // as seen this frame; returns the id of the tile that took most of them.
  int placeCells(int plane_id, const std::vector<Cell>& cells);
  Patch& tileAt(int plane_id, const Cell& key);
  Patch& patchWithId(int id);
  // The plane's tiles, in id order.
  std::vector<Patch*> tilesOf(const Plane& plane);
  void finalize(Patch& patch, std::vector<PatchEvent>& events, const char* reason) const;
  // Whether a patch of this area is finalized (min_area_m2; a tile finalized before always).
  bool largeEnough(const Patch& patch, double area_m2) const;
  // Loads a released patch's samples back (a region continues it).
  void restoreSamples(Patch& patch) const;

  PatchMapConfig config_;
  std::map<int, Patch> patches_;  // the tiles, by patch id
  std::size_t tiles_moved_within_planes_ = 0;
  std::set<int> moving_planes_;   // plane ids with tiles due to move within them
  std::map<int, Plane> planes_;   // by plane id
  std::set<int> seen_this_frame_;
  std::set<int> set_aside_;          // plane ids (setAsideAll)
  std::vector<PatchEvent> pending_;  // retirements from merges, reported by endFrame
  Eigen::Vector3f last_gain_ = Eigen::Vector3f::Ones();
  int next_id_ = 0;  // of tiles (patches)
  int next_plane_id_ = 0;
  std::optional<std::filesystem::path> spill_dir_;
  std::size_t samples_released_ = 0;
  bool spill_failed_ = false;  // warned once
};

}  // namespace tessera::planes
