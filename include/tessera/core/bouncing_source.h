#pragma once
// A recording played back and forth: forwards, then backwards, then forwards again, as many
// passes as asked. A short real clip becomes a long stream whose camera path never jumps (it
// turns round at each end), for measuring a run's steady state on real frames (`tessera run
// --bounce N`, `tessera play --bounce N`). Frames of the first pass are kept in memory.
#include <cstdint>
#include <memory>
#include <vector>

#include "tessera/core/frame_source.h"

namespace tessera::core {

class BouncingSource : public FrameSource {
 public:
  // Frames kept for the passes after the first, at most: beyond it the stream ends after the
  // first pass, with a warning.
  static constexpr std::size_t kMaxKeptBytes = std::size_t{2} << 30;

  // passes >= 1 (1: the recording as it is). Throws ConfigError for a live source or passes < 1.
  BouncingSource(std::unique_ptr<FrameSource> recording, int passes);

  ReadResult read() override;
  std::string name() const override { return recording_->name(); }
  std::optional<std::size_t> frameCount() const override;

 private:
  // Frame `kept_[at]` as the next one out: numbered on, stamped after the last one by the
  // recording's own interval between the two, its colour's lead mirrored on a backward pass.
  ReadResult replay(std::size_t at);

  std::unique_ptr<FrameSource> recording_;
  int passes_;
  std::vector<Frame> kept_;
  std::size_t kept_bytes_ = 0;
  bool too_long_ = false;
  std::string end_problem_;  // the recording's own, reported when the last pass ends
  int pass_ = 0;             // 0: the first, straight from the recording
  std::size_t next_ = 0;     // position in kept_ on later passes
  std::uint64_t emitted_ = 0;
  std::int64_t last_stamp_ = 0;
  std::size_t last_at_ = 0;  // kept_ position of the last frame out
};

}  // namespace tessera::core
