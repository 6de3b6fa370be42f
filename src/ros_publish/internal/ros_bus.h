#pragma once
// The ROS side of the publisher, in plain types: the files that include ROS 1's message
// headers are compiled as C++17 (drivers/ros1/CMakeLists.txt says why), and this header is
// what they share with the rest.
#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

namespace tessera::ros_publish::internal {

// Triangles in the map frame, three vertices each, with a colour (R, G, B in 0..1) per vertex.
struct ColouredMesh {
  int id = 0;
  std::vector<Eigen::Vector3f> vertices;
  std::vector<std::array<float, 3>> colours;
};

enum class Level { kOk = 0, kWarn = 1, kError = 2 };

class RosBus {
 public:
  RosBus(const std::string& master_uri, std::string map_frame, std::string camera_frame);
  ~RosBus();

  // stamp_ns 0: now.
  void publishPose(std::int64_t stamp_ns, const Eigen::Isometry3d& T_map_camera);
  void publishPatch(ColouredMesh mesh);
  void deletePatch(int id);
  void publishFigures(const std::string& name, const std::string& hardware_id, Level level,
                      const std::string& message,
                      const std::vector<std::pair<std::string, std::string>>& values,
                      const std::string& figures_json);
  void publishFiles(const std::vector<std::string>& files);

 private:
  struct Topics;
  std::unique_ptr<Topics> topics_;
};

}  // namespace tessera::ros_publish::internal
