#pragma once
// The keyframes of a map as a file, for a later session to relocalise against
// (`tessera run --continue`): each one's time, pose and ORB features.
#include <filesystem>
#include <vector>

#include "tessera/fusion/tracker.h"

namespace tessera::fusion {

// Throws core::Error naming the file when it cannot be written.
void writeMapKeyframes(const std::filesystem::path& path,
                       const std::vector<MapKeyframe>& keyframes);
// Throws core::Error naming a missing, corrupt or newer file.
std::vector<MapKeyframe> readMapKeyframes(const std::filesystem::path& path);

}  // namespace tessera::fusion
