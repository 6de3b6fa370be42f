// The memory figures of a long run: the heap in use follows what the program holds,
// returning freed memory gives the kernel back pages that a live block above them pinned, and
// after the frames freed memory goes back as it is freed.
// Sanitizer builds replace malloc, so there these figures mean nothing and the tests skip.
#include <malloc.h>

#include <cstring>
#include <memory>
#include <vector>

#include <gtest/gtest.h>

#include "tessera/core/memory.h"

namespace tessera::core {
namespace {

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool kSanitized = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif
#else
constexpr bool kSanitized = false;
#endif

// 2,000 blocks of 40 KB (80 MB), each below glibc's mmap threshold (set here, whatever the
// environment says) so that they share the heap, every byte written so that the pages are
// resident.
std::vector<std::unique_ptr<char[]>> manySmallBlocks() {
  mallopt(M_MMAP_THRESHOLD, 1 << 20);
  std::vector<std::unique_ptr<char[]>> blocks(2000);
  for (auto& block : blocks) {
    block = std::make_unique<char[]>(40'000);
    std::memset(block.get(), 1, 40'000);
  }
  return blocks;
}

TEST(Memory, HeapInUseFollowsWhatIsHeld) {
  if (kSanitized) GTEST_SKIP() << "a sanitizer's allocator keeps its own figures";
  const double before = heapInUseMb();
  auto blocks = manySmallBlocks();
  EXPECT_NEAR(heapInUseMb() - before, 80.0, 4.0);
  blocks.clear();
  EXPECT_NEAR(heapInUseMb() - before, 0.0, 4.0);
}

TEST(Memory, ReturningFreedMemoryLowersTheResidentSize) {
  if (kSanitized) GTEST_SKIP() << "a sanitizer's allocator keeps its own figures";
  auto blocks = manySmallBlocks();
  // Freed except the last: the heap cannot shrink from its top, so glibc keeps the pages.
  std::unique_ptr<char[]> last = std::move(blocks.back());
  blocks.clear();
  const double kept = residentMb();
  returnFreedMemory();
  EXPECT_GT(kept - residentMb(), 40.0) << "resident " << kept << " MB before";
  EXPECT_GT(residentMb(), 0.0);
}

// `count` blocks of 1 MB, written.
std::vector<std::unique_ptr<char[]>> megabytes(int count) {
  std::vector<std::unique_ptr<char[]>> blocks(static_cast<std::size_t>(count));
  for (auto& block : blocks) {
    block = std::make_unique<char[]>(1 << 20);
    std::memset(block.get(), 1, 1 << 20);
  }
  return blocks;
}

TEST(Memory, AfterTheFramesFreedMemoryGoesBackAsItIsFreed) {
  if (kSanitized) GTEST_SKIP() << "a sanitizer's allocator keeps its own figures";
  if (userSetMallocTunables()) {
    GTEST_SKIP() << "GLIBC_TUNABLES sets malloc tunables, which tessera leaves alone";
  }
  keepFreedMemoryForReuse(2);
  // Read once before: the first read allocates what the stream keeps for good, which would
  // otherwise sit above the blocks and keep the heap from shrinking.
  residentMb();
  returnFreedMemory();
  // During the frames: 48 MB freed at the heap's top stay resident for the next frame.
  auto blocks = megabytes(48);
  const double held = residentMb();
  blocks.clear();
  EXPECT_LT(held - residentMb(), 8.0) << "resident " << held << " MB while held";

  returnFreedMemorySooner();  // the frames are over
  blocks = megabytes(48);
  const double held_again = residentMb();
  blocks.clear();  // no malloc_trim: the free itself hands the top back
  EXPECT_GT(held_again - residentMb(), 32.0) << "resident " << held_again << " MB while held";
}

}  // namespace
}  // namespace tessera::core
