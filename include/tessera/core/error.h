#pragma once
// Error types. Problems that stop a run (bad config, unreadable source) are exceptions;
// a single bad frame is not: sources report it through ReadStatus::kBadFrame.
#include <stdexcept>
#include <string>

namespace tessera::core {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A configuration file or command-line value that cannot be used.
class ConfigError : public Error {
 public:
  using Error::Error;
};

// A frame source (recording, folder, device) that cannot be opened or read at all.
class SourceError : public Error {
 public:
  using Error::Error;
};

}  // namespace tessera::core
