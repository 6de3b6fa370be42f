// A recording played back and forth: the frames' order, their numbers, stamps that keep
// rising by the recording's own intervals, colour leads mirrored on the way back, and what a
// live source or a bad pass count gets.
#include "tessera/core/bouncing_source.h"

#include <gtest/gtest.h>

#include "tessera/core/error.h"

namespace tessera::core {
namespace {

// Frames 0..count-1 at uneven intervals (10, 20, 30, ... ms), colour 3 ms after depth; each
// frame's depth holds its own number.
class ListSource : public FrameSource {
 public:
  ListSource(int count, bool live = false, std::string end_problem = {})
      : count_(count), live_(live), end_problem_(std::move(end_problem)) {}
  ReadResult read() override {
    if (next_ == count_) return {ReadStatus::kEndOfData, {}, end_problem_};
    ReadResult result;
    result.status = ReadStatus::kFrame;
    result.frame.index = static_cast<std::uint64_t>(next_);
    result.frame.timestamp_ns = stampOf(next_);
    result.frame.colour_timestamp_ns = stampOf(next_) + 3'000'000;
    result.frame.depth_mm = cv::Mat(2, 2, CV_16UC1, cv::Scalar(next_));
    ++next_;
    return result;
  }
  std::string name() const override { return "list"; }
  std::optional<std::size_t> frameCount() const override {
    return static_cast<std::size_t>(count_);
  }
  bool isLive() const override { return live_; }
  static std::int64_t stampOf(int i) { return 5'000'000LL * i * (i + 1); }  // 10, 20, 30 ms apart

 private:
  int count_, next_ = 0;
  bool live_;
  std::string end_problem_;
};

TEST(BouncingSource, PlaysForwardsBackwardsAndForwardsWithRisingStamps) {
  BouncingSource source(std::make_unique<ListSource>(4), 3);
  EXPECT_EQ(source.frameCount(), 10u);  // 4 + 3 + 3
  std::vector<int> order;
  std::vector<std::int64_t> stamps, leads;
  for (ReadResult r = source.read(); r.status == ReadStatus::kFrame; r = source.read()) {
    EXPECT_EQ(r.frame.index, order.size());
    order.push_back(r.frame.depth_mm.at<std::uint16_t>(0, 0));
    stamps.push_back(r.frame.timestamp_ns);
    leads.push_back(*r.frame.colour_timestamp_ns - r.frame.timestamp_ns);
  }
  EXPECT_EQ(order, (std::vector<int>{0, 1, 2, 3, 2, 1, 0, 1, 2, 3}));
  // Each step lasts what the same step lasted in the recording, whichever way it is played.
  for (std::size_t k = 1; k < order.size(); ++k) {
    EXPECT_EQ(stamps[k] - stamps[k - 1],
              std::llabs(ListSource::stampOf(order[k]) - ListSource::stampOf(order[k - 1])))
        << "step " << k;
  }
  EXPECT_EQ(leads,
            (std::vector<std::int64_t>{3'000'000, 3'000'000, 3'000'000, 3'000'000, -3'000'000,
                                       -3'000'000, -3'000'000, 3'000'000, 3'000'000, 3'000'000}));
}

TEST(BouncingSource, OnePassIsTheRecordingAndTheRecordingsEndProblemComesLast) {
  BouncingSource once(std::make_unique<ListSource>(3, false, "cut off"), 1);
  int frames = 0;
  ReadResult r = once.read();
  for (; r.status == ReadStatus::kFrame; r = once.read()) ++frames;
  EXPECT_EQ(frames, 3);
  EXPECT_EQ(r.problem, "cut off");

  BouncingSource twice(std::make_unique<ListSource>(3, false, "cut off"), 2);
  frames = 0;
  r = twice.read();
  for (; r.status == ReadStatus::kFrame; r = twice.read()) ++frames;
  EXPECT_EQ(frames, 5);
  EXPECT_EQ(r.status, ReadStatus::kEndOfData);
  EXPECT_EQ(r.problem, "cut off");
}

TEST(BouncingSource, RefusesALiveSourceAndFewerThanOnePass) {
  EXPECT_THROW(BouncingSource(std::make_unique<ListSource>(3, true), 2), ConfigError);
  EXPECT_THROW(BouncingSource(std::make_unique<ListSource>(3), 0), ConfigError);
}

}  // namespace
}  // namespace tessera::core
