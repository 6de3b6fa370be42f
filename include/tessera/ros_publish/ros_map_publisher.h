#pragma once
// A run's map and figures on a ROS 1 graph, as RViz and a robot's other nodes expect them
// (docs/ROS.md):
//   /tf                    map -> camera frame, every frame (tf2_msgs/TFMessage)
//   /tessera/pose          the same pose (geometry_msgs/PoseStamped)
//   /tessera/patches       each committed patch as a vertex-coloured triangle list
//                          (visualization_msgs/MarkerArray); a new subscriber gets them all
//   /diagnostics           the map's figures at about 1 Hz (diagnostic_msgs/DiagnosticArray)
//   /tessera/figures       the same figures as the monitor's /stats JSON (std_msgs/String)
//   /tessera/map_files     latched: the exported files, one path per line (std_msgs/String)
#include <atomic>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "tessera/pipeline/map_monitor.h"
#include "tessera/pipeline/run_listener.h"

namespace tessera::ros_publish {

namespace internal {
class RosBus;
}

struct RosPublisherOptions {
  std::string master_uri;  // empty: ROS_MASTER_URI, else http://localhost:11311
  std::string map_frame = "map";
  std::string camera_frame = "tessera_camera";
  // Stamp poses with the frames' own time (a ROS source: the images' ROS time), or with the
  // time they are published (replays, whose clock is the recording's).
  bool stamp_with_frame_time = true;
  double figures_period_s = 1.0;
  int max_quads_per_patch = 4000;  // a patch's marker is its bitmap in at most this many cells
};

// Thread-safe: the pipeline's nodes call it; its own thread publishes the figures.
class RosMapPublisher : public pipeline::RunListener {
 public:
  // Throws core::SourceError naming the master when it cannot be reached.
  RosMapPublisher(const RosPublisherOptions& options, const pipeline::MapMonitor& monitor,
                  std::string source_name);
  ~RosMapPublisher() override;

  void onPose(std::int64_t timestamp_ns, const core::Isometry& T_W_C) override;
  void onPatch(const pipeline::PatchSurface& patch) override;
  void onPatchRetired(int patch_id) override;
  void onExported(const std::vector<std::filesystem::path>& files) override;

 private:
  void publishFigures();
  void figuresLoop();

  RosPublisherOptions options_;
  const pipeline::MapMonitor& monitor_;
  std::string source_name_;
  std::unique_ptr<internal::RosBus> bus_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stopping_ = false;  // guarded by mutex_
  std::thread figures_thread_;
};

}  // namespace tessera::ros_publish
