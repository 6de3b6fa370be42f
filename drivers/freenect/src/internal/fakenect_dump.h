#pragma once
// Debian's fakenect: a stand-in libfreenect (found first through LD_LIBRARY_PATH) that replays
// a dump folder recorded by libfreenect's `record` tool instead of talking to a device.
//
// The dump format, as the library reads it: FAKENECT_PATH/INDEX.txt lists one file name per
// line, replayed in order until the first empty line; a name is TYPE-HOSTTIME-TIMESTAMP-REST
// (printf "%c-%f-%u-%s": TYPE 'd' depth, 'r' RGB, 'a' accelerometer; HOSTTIME in seconds paces
// the replay; TIMESTAMP the device clock handed to the callbacks). A 'd' file is a one-line
// PGM header ("P5 640 480 65535\n") followed by 640x480 raw 11-bit disparities as host-order
// (little-endian) uint16, not the big-endian samples a real PGM holds; an 'r' file a one-line
// PPM header followed by 640x480x3 RGB bytes; an 'a' file a freenect_raw_tilt_state. fakenect
// offers only FREENECT_DEPTH_11BIT and FREENECT_VIDEO_RGB at 640x480 (it asserts on others).
//
// fakenect ends the process on a missing file or a header without a newline, and reads past
// the end of a truncated frame, so a dump is checked before it is replayed.
#include <filesystem>
#include <optional>
#include <string>

namespace tessera::drivers::freenect {

// Whether the libfreenect loaded into this process is fakenect.
bool fakenectLoaded();

// With fakenect loaded: the dump folder it will replay (FAKENECT_PATH). Throws
// core::SourceError naming `label` when FAKENECT_PATH is not set. Without fakenect: nothing.
std::optional<std::filesystem::path> fakenectDump(const std::string& label);

// Checks that fakenect can replay every file the dump's INDEX.txt lists: a parsable name, a
// readable file, a header line and a whole frame. Throws core::SourceError naming the file and
// what is wrong. Returns the number of depth frames listed.
std::size_t checkFakenectDump(const std::filesystem::path& folder);

}  // namespace tessera::drivers::freenect
