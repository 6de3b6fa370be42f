#pragma once
// Where tests find data: the committed recordings and the shared real data beside the clone.
#include <filesystem>

#include <gtest/gtest.h>

namespace tessera::test {

inline std::filesystem::path sourceDir() { return TESSERA_SOURCE_DIR; }

inline std::filesystem::path sharedData() { return TESSERA_SHARED_DATA_DIR; }

// A fresh, empty temporary folder named after the running test.
inline std::filesystem::path freshTempDir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const auto dir = std::filesystem::temp_directory_path() / "tessera_tests" /
                   (std::string(info->test_suite_name()) + "." + info->name());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace tessera::test

// Skips the current test, saying why, when a folder of ../shared/data is absent (a user's
// clone has no ../shared).
#define TESSERA_REQUIRE_SHARED(relative)                                              \
  do {                                                                                \
    if (!std::filesystem::is_directory(::tessera::test::sharedData() / (relative))) { \
      GTEST_SKIP() << "shared test data not found: "                                  \
                   << (::tessera::test::sharedData() / (relative)).string()           \
                   << " (clone with ../shared beside it to run this test)";           \
    }                                                                                 \
  } while (0)
