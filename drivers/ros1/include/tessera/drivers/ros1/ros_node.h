#pragma once
// roscpp's process-wide node: started once, by the first ROS source or publisher, against one
// master.
#include <string>

namespace tessera::drivers::ros1 {

// "http://HOST:PORT" from `master_uri`, else ROS_MASTER_URI, else the default master.
std::string resolveMasterUri(const std::string& master_uri);

// Starts roscpp as node "tessera" (made unique), with its own spinner threads and without
// roscpp's Ctrl-C handler (tessera's own ends the run), and checks that the master answers.
// Throws core::SourceError naming the master when it does not, or core::ConfigError when the
// node already runs against another master.
void ensureRosNode(const std::string& master_uri);

}  // namespace tessera::drivers::ros1
