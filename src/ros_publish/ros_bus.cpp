#include "internal/ros_bus.h"

#include <mutex>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <geometry_msgs/PoseStamped.h>
#include <ros/ros.h>
#include <std_msgs/String.h>
#include <tf2_msgs/TFMessage.h>
#include <visualization_msgs/MarkerArray.h>

#include "tessera/drivers/ros1/ros_node.h"

namespace tessera::ros_publish::internal {

namespace {

ros::Time stampOf(std::int64_t stamp_ns) {
  if (stamp_ns <= 0) return ros::Time::now();
  ros::Time time;
  time.fromNSec(static_cast<std::uint64_t>(stamp_ns));
  return time;
}

}  // namespace

struct RosBus::Topics {
  std::string map_frame, camera_frame;
  ros::Publisher tf, pose, patches, diagnostics, figures, files;
  std::mutex mutex;                                   // guards markers
  std::map<int, visualization_msgs::Marker> markers;  // every patch in the map, by id

  // The marker of patch `id`, stamped now in the map frame; the caller says what it does.
  visualization_msgs::Marker patchMarker(int id) const {
    visualization_msgs::Marker marker;
    marker.header.stamp = ros::Time::now();
    marker.header.frame_id = map_frame;
    marker.ns = "tessera_patches";
    marker.id = id;
    return marker;
  }

  // A subscriber that joins late (RViz started after the run) gets the whole map at once.
  void sendAll(const ros::SingleSubscriberPublisher& subscriber) {
    visualization_msgs::MarkerArray all;
    {
      std::lock_guard lock(mutex);
      for (const auto& [id, marker] : markers) all.markers.push_back(marker);
    }
    if (!all.markers.empty()) subscriber.publish(all);
  }
};

RosBus::RosBus(const std::string& master_uri, std::string map_frame, std::string camera_frame)
    : topics_(std::make_unique<Topics>()) {
  drivers::ros1::ensureRosNode(master_uri);
  Topics& t = *topics_;
  t.map_frame = std::move(map_frame);
  t.camera_frame = std::move(camera_frame);
  ros::NodeHandle node;
  t.tf = node.advertise<tf2_msgs::TFMessage>("/tf", 100);
  t.pose = node.advertise<geometry_msgs::PoseStamped>("/tessera/pose", 10);
  t.patches = node.advertise<visualization_msgs::MarkerArray>(
      "/tessera/patches", 100, [&t](const ros::SingleSubscriberPublisher& s) { t.sendAll(s); });
  t.diagnostics = node.advertise<diagnostic_msgs::DiagnosticArray>("/diagnostics", 10);
  t.figures = node.advertise<std_msgs::String>("/tessera/figures", 10);
  t.files = node.advertise<std_msgs::String>("/tessera/map_files", 1, /*latch=*/true);
}

RosBus::~RosBus() {
  Topics& t = *topics_;
  for (ros::Publisher* publisher :
       {&t.tf, &t.pose, &t.patches, &t.diagnostics, &t.figures, &t.files}) {
    publisher->shutdown();
  }
}

void RosBus::publishPose(std::int64_t stamp_ns, const Eigen::Isometry3d& T_map_camera) {
  Topics& t = *topics_;
  geometry_msgs::PoseStamped pose;
  pose.header.stamp = stampOf(stamp_ns);
  pose.header.frame_id = t.map_frame;
  const Eigen::Quaterniond q(T_map_camera.rotation());
  pose.pose.position.x = T_map_camera.translation().x();
  pose.pose.position.y = T_map_camera.translation().y();
  pose.pose.position.z = T_map_camera.translation().z();
  pose.pose.orientation.x = q.x();
  pose.pose.orientation.y = q.y();
  pose.pose.orientation.z = q.z();
  pose.pose.orientation.w = q.w();
  geometry_msgs::TransformStamped transform;
  transform.header = pose.header;
  transform.child_frame_id = t.camera_frame;
  transform.transform.translation.x = pose.pose.position.x;
  transform.transform.translation.y = pose.pose.position.y;
  transform.transform.translation.z = pose.pose.position.z;
  transform.transform.rotation = pose.pose.orientation;
  tf2_msgs::TFMessage tf;
  tf.transforms.push_back(transform);
  t.tf.publish(tf);
  t.pose.publish(pose);
}

void RosBus::publishPatch(ColouredMesh mesh) {
  Topics& t = *topics_;
  visualization_msgs::Marker marker = t.patchMarker(mesh.id);
  marker.type = visualization_msgs::Marker::TRIANGLE_LIST;
  marker.action = visualization_msgs::Marker::ADD;
  marker.pose.orientation.w = 1.0;
  marker.scale.x = marker.scale.y = marker.scale.z = 1.0;
  marker.color.r = marker.color.g = marker.color.b = marker.color.a = 1.0f;
  marker.points.resize(mesh.vertices.size());
  marker.colors.resize(mesh.colours.size());
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    marker.points[i].x = mesh.vertices[i].x();
    marker.points[i].y = mesh.vertices[i].y();
    marker.points[i].z = mesh.vertices[i].z();
  }
  for (std::size_t i = 0; i < mesh.colours.size(); ++i) {
    marker.colors[i].r = mesh.colours[i][0];
    marker.colors[i].g = mesh.colours[i][1];
    marker.colors[i].b = mesh.colours[i][2];
    marker.colors[i].a = 1.0f;
  }
  visualization_msgs::MarkerArray update;
  update.markers.push_back(marker);
  {
    std::lock_guard lock(t.mutex);
    t.markers[mesh.id] = marker;
  }
  t.patches.publish(update);
}

void RosBus::deletePatch(int id) {
  Topics& t = *topics_;
  visualization_msgs::Marker marker = t.patchMarker(id);
  marker.action = visualization_msgs::Marker::DELETE;
  {
    std::lock_guard lock(t.mutex);
    t.markers.erase(id);
  }
  visualization_msgs::MarkerArray update;
  update.markers.push_back(marker);
  t.patches.publish(update);
}

void RosBus::publishFigures(const std::string& name, const std::string& hardware_id, Level level,
                            const std::string& message,
                            const std::vector<std::pair<std::string, std::string>>& values,
                            const std::string& figures_json) {
  Topics& t = *topics_;
  diagnostic_msgs::DiagnosticStatus status;
  status.level = static_cast<std::uint8_t>(level);
  status.name = name;
  status.message = message;
  status.hardware_id = hardware_id;
  for (const auto& [key, value] : values) {
    diagnostic_msgs::KeyValue pair;
    pair.key = key;
    pair.value = value;
    status.values.push_back(pair);
  }
  diagnostic_msgs::DiagnosticArray array;
  array.header.stamp = ros::Time::now();
  array.status.push_back(status);
  t.diagnostics.publish(array);
  std_msgs::String json;
  json.data = figures_json;
  t.figures.publish(json);
}

void RosBus::publishFiles(const std::vector<std::string>& files) {
  std_msgs::String list;
  for (const std::string& file : files) list.data += file + "\n";
  topics_->files.publish(list);
}

}  // namespace tessera::ros_publish::internal
