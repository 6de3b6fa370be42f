#pragma once
// Text files the program writes (OBJ, MTL, JSON): one clear error naming the file when it
// cannot be created or when writing it fails (a full disk shows at the close).
#include <filesystem>
#include <fstream>

namespace tessera::core {

// Opens `path` for writing; throws core::Error naming it if it cannot be created.
std::ofstream createOutputFile(const std::filesystem::path& path);
// Closes `out`; throws core::Error naming `path` if anything written to it was lost.
void finishOutputFile(std::ofstream& out, const std::filesystem::path& path);

// A second name `to` for the file `from` (a copy where the file system has no hard links),
// replacing what `to` named. Safe for files that are never rewritten in place: those written
// anew are written under a new name and renamed over the old one.
void linkOrCopy(const std::filesystem::path& from, const std::filesystem::path& to);

}  // namespace tessera::core
