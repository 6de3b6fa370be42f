// The depth/colour inbox the live sources share: a busy reader loses the oldest depth frames
// (counted), each depth frame takes the colour frame nearest in time within the tolerance,
// older colour frames go with it, colour frames are kept in stamp order, and a colour frame
// still on its way is waited for, longer while the colour stream has not started.
#include "tessera/core/frame_pairing.h"

#include <thread>

#include <gtest/gtest.h>

namespace tessera::core {
namespace {

CapturedImage at(std::int64_t stamp) {
  CapturedImage image;
  image.stamp = stamp;
  image.image = cv::Mat(2, 2, CV_8UC1, cv::Scalar(static_cast<double>(stamp % 256)));
  return image;
}

TEST(PairingInbox, DropsTheOldestDepthFramesBeyondCapacityAndCountsThem) {
  PairingInbox inbox;
  inbox.depth_capacity = 2;
  for (int i = 0; i < 5; ++i) inbox.pushDepth(at(i * 33));
  inbox.pushDepth(at(200), 2);  // two frames the device sent never arrived
  EXPECT_EQ(inbox.delivered, 8u);
  EXPECT_EQ(inbox.dropped, 6u);  // 4 pushed out, 2 missed
  ASSERT_EQ(inbox.depth.size(), 2u);
  EXPECT_EQ(inbox.depth.front().stamp, 132);
}

TEST(PairingInbox, TakesTheNearestColourWithinToleranceAndDropsOlderOnes) {
  PairingInbox inbox;
  for (std::int64_t t : {0, 33, 66, 99}) inbox.pushColour(at(t));
  std::unique_lock lock(inbox.mutex);
  const auto colour = inbox.takeColourNear(lock, 70, 16, std::chrono::microseconds(0));
  ASSERT_TRUE(colour);
  EXPECT_EQ(colour->stamp, 66);
  ASSERT_EQ(inbox.colour.size(), 1u);  // 0, 33 and 66 gone
  EXPECT_EQ(inbox.colour.front().stamp, 99);
  // Nothing within 16 of 140: no pair, and the queue keeps what it has.
  EXPECT_FALSE(inbox.takeColourNear(lock, 140, 16, std::chrono::microseconds(0)));
  EXPECT_EQ(inbox.colour.size(), 1u);
}

TEST(PairingInbox, KeepsColourFramesHandedOverOutOfOrderInStampOrder) {
  PairingInbox inbox;
  inbox.colour_capacity = 3;
  for (std::int64_t t : {0, 66, 33, 99}) inbox.pushColour(at(t));  // 0 leaves: capacity 3
  ASSERT_EQ(inbox.colour.size(), 3u);
  EXPECT_EQ(inbox.colour[0].stamp, 33);
  EXPECT_EQ(inbox.colour[1].stamp, 66);
  EXPECT_EQ(inbox.colour[2].stamp, 99);
  // The late 33 pairs with a depth frame at 35 and leaves 66 and 99 for the frames after it.
  std::unique_lock lock(inbox.mutex);
  const auto colour = inbox.takeColourNear(lock, 35, 16, std::chrono::microseconds(0));
  ASSERT_TRUE(colour);
  EXPECT_EQ(colour->stamp, 33);
  EXPECT_EQ(inbox.colour.size(), 2u);
}

TEST(PairingInbox, WaitsForAColourFrameStillOnItsWay) {
  PairingInbox inbox;
  inbox.pushColour(at(0));
  std::thread device([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const std::lock_guard lock(inbox.mutex);
    inbox.pushColour(at(33));
  });
  std::unique_lock lock(inbox.mutex);
  const auto colour = inbox.takeColourNear(lock, 34, 16, std::chrono::seconds(5));
  lock.unlock();
  device.join();
  ASSERT_TRUE(colour);
  EXPECT_EQ(colour->stamp, 33);
}

// A colour stream starts after depth: the first depth frame waits longer for its colour than
// the ones after it, and a new connection starts over.
TEST(PairingInbox, WaitsLongerForTheColourStreamToStart) {
  PairingInbox inbox;
  const auto usual = std::chrono::microseconds(66'000);
  EXPECT_EQ(inbox.colourWait(usual), inbox.colour_start_wait);
  inbox.pushColour(at(0));
  EXPECT_EQ(inbox.colourWait(usual), usual);
  inbox.clearFrames();
  EXPECT_EQ(inbox.colourWait(usual), inbox.colour_start_wait);
}

}  // namespace
}  // namespace tessera::core
