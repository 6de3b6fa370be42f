#include "tessera/core/bouncing_source.h"

#include <cstdlib>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "tessera/core/error.h"

namespace tessera::core {

namespace {

std::size_t frameBytes(const Frame& frame) {
  return frame.depth_mm.total() * frame.depth_mm.elemSize() +
         frame.rgb.total() * frame.rgb.elemSize();
}

}  // namespace

BouncingSource::BouncingSource(std::unique_ptr<FrameSource> recording, int passes)
    : recording_(std::move(recording)), passes_(passes) {
  if (passes_ < 1) throw ConfigError(fmt::format("--bounce {}: must be at least 1", passes_));
  if (recording_->isLive()) {
    throw ConfigError(fmt::format(
        "--bounce: {} is live; only a recording or dataset can be played back and forth",
        recording_->name()));
  }
}

std::optional<std::size_t> BouncingSource::frameCount() const {
  const std::optional<std::size_t> count = recording_->frameCount();
  if (!count || *count == 0) return count;
  // Each later pass leaves out the frame it turns round at (shown by the pass before).
  return *count + static_cast<std::size_t>(passes_ - 1) * (*count - 1);
}

ReadResult BouncingSource::read() {
  if (pass_ == 0) {
    ReadResult result = recording_->read();
    if (result.status == ReadStatus::kFrame) {
      result.frame.index = emitted_++;
      last_stamp_ = result.frame.timestamp_ns;
      if (passes_ > 1 && !too_long_) {
        kept_bytes_ += frameBytes(result.frame);
        if (kept_bytes_ > kMaxKeptBytes) {
          too_long_ = true;
          kept_.clear();
          spdlog::warn("--bounce: {} holds more than {} MB of frames; it plays once", name(),
                       kMaxKeptBytes >> 20);
        } else {
          kept_.push_back(result.frame);
          last_at_ = kept_.size() - 1;
        }
      }
      return result;
    }
    if (result.status != ReadStatus::kEndOfData) return result;
    end_problem_ = result.problem;
    if (kept_.size() < 2) return result;
    pass_ = 1;
    next_ = kept_.size() - 2;
  }
  if (pass_ >= passes_) return {ReadStatus::kEndOfData, {}, end_problem_};
  ReadResult result = replay(next_);
  const bool backward = pass_ % 2 == 1;
  const bool turning = backward ? next_ == 0 : next_ + 1 == kept_.size();
  if (turning) {
    ++pass_;
    next_ = backward ? 1 : kept_.size() - 2;
  } else {
    next_ = backward ? next_ - 1 : next_ + 1;
  }
  return result;
}

ReadResult BouncingSource::replay(std::size_t at) {
  ReadResult result;
  result.status = ReadStatus::kFrame;
  result.frame = kept_[at];  // cv::Mat shares the pixels
  Frame& frame = result.frame;
  const std::int64_t original = frame.timestamp_ns;
  last_stamp_ += std::llabs(original - kept_[last_at_].timestamp_ns);
  last_at_ = at;
  frame.index = emitted_++;
  frame.timestamp_ns = last_stamp_;
  if (frame.colour_timestamp_ns) {
    // Played backwards, colour taken after its depth image comes before it.
    const std::int64_t lead = *frame.colour_timestamp_ns - original;
    frame.colour_timestamp_ns = last_stamp_ + (pass_ % 2 == 1 ? -lead : lead);
  }
  return result;
}

}  // namespace tessera::core
