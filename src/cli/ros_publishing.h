#pragma once
// `tessera run --publish`: the map out on a ROS 1 graph, when tessera is built with ROS 1.
#include <memory>
#include <string>

#include "run_command.h"
#include "tessera/pipeline/map_monitor.h"
#include "tessera/pipeline/run_listener.h"

namespace tessera::cli {

// The publisher --publish asks for (a ros:// source's graph by default), or null for none.
// Throws core::ConfigError for a bad --publish, or when tessera was built without ROS 1, and
// core::SourceError naming a master that does not answer.
std::unique_ptr<pipeline::RunListener> openMapPublisher(const RunArguments& args,
                                                        const std::string& source_spec,
                                                        const pipeline::MapMonitor& monitor);

}  // namespace tessera::cli
