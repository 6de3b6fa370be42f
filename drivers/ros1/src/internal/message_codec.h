#pragma once
// ROS 1 messages to and from their serialized bytes, and geometry messages to and from
// tessera's poses.
#include <algorithm>
#include <cstdint>
#include <new>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <geometry_msgs/Pose.h>
#include <geometry_msgs/Transform.h>
#include <ros/serialization.h>

#include "internal/bag_messages.h"
#include "tessera/core/error.h"
#include "tessera/core/pose.h"

namespace tessera::drivers::ros1 {

// Throws core::SourceError when the bytes are not a whole message of type M.
template <typename M>
M decode(const RawMessage& raw) {
  M message;
  try {
    ros::serialization::IStream stream(const_cast<std::uint8_t*>(raw.bytes.data()),
                                       static_cast<std::uint32_t>(raw.bytes.size()));
    ros::serialization::deserialize(stream, message);
  } catch (const ros::Exception& e) {
    throw core::SourceError(
        fmt::format("a {} message that cannot be read: {}", raw.datatype, e.what()));
  } catch (const std::bad_alloc&) {
    // A corrupt array length: the deserialiser sizes the array before it finds the data short.
    throw core::SourceError(
        fmt::format("a {} message of {} bytes that claims an array larger than memory",
                    raw.datatype, raw.bytes.size()));
  }
  return message;
}

// ROS time from nanoseconds (negative: 0).
inline ros::Time rosTime(std::int64_t ns) {
  ros::Time time;
  time.fromNSec(static_cast<std::uint64_t>(std::max<std::int64_t>(ns, 0)));
  return time;
}

inline core::Isometry isometryFromTransform(const geometry_msgs::Transform& t) {
  return core::isometryFromTranslationQuaternion(
      {t.translation.x, t.translation.y, t.translation.z}, t.rotation.x, t.rotation.y, t.rotation.z,
      t.rotation.w);
}

inline core::Isometry isometryFromPose(const geometry_msgs::Pose& p) {
  return core::isometryFromTranslationQuaternion({p.position.x, p.position.y, p.position.z},
                                                 p.orientation.x, p.orientation.y, p.orientation.z,
                                                 p.orientation.w);
}

inline geometry_msgs::Transform transformFromIsometry(const core::Isometry& T) {
  geometry_msgs::Transform t;
  const Eigen::Quaterniond q(T.rotation());
  t.translation.x = T.translation().x();
  t.translation.y = T.translation().y();
  t.translation.z = T.translation().z();
  t.rotation.x = q.x();
  t.rotation.y = q.y();
  t.rotation.z = q.z();
  t.rotation.w = q.w();
  return t;
}

}  // namespace tessera::drivers::ros1
