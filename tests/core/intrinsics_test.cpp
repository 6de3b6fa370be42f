#include <fstream>

#include <gtest/gtest.h>

#include "support/test_data.h"
#include "tessera/core/error.h"
#include "tessera/core/intrinsics.h"

namespace tessera::core {
namespace {

TEST(Intrinsics, ParsesFourOrSixValues) {
  const Intrinsics k = parseIntrinsicsSpec("517.3,516.5,318.6,255.3");
  EXPECT_DOUBLE_EQ(k.fx, 517.3);
  EXPECT_DOUBLE_EQ(k.cy, 255.3);
  EXPECT_EQ(k.width, 0);
  const Intrinsics sized = parseIntrinsicsSpec("481.2,-480,319.5,239.5,640,480");
  EXPECT_DOUBLE_EQ(sized.fy, -480.0);
  EXPECT_EQ(sized.width, 640);
  EXPECT_TRUE(sized.valid());
}

TEST(Intrinsics, RejectsMalformedValues) {
  EXPECT_THROW(parseIntrinsicsSpec("517.3,516.5,318.6"), ConfigError);
  EXPECT_THROW(parseIntrinsicsSpec("517.3,516.5,318.6,2x5"), ConfigError);
  EXPECT_THROW(parseIntrinsicsSpec("0,516.5,318.6,255.3"), ConfigError);
}

TEST(Intrinsics, ReadsYamlFileAndRejectsUnknownKeys) {
  const auto dir = test::freshTempDir();
  std::ofstream(dir / "k.yaml")
      << "fx: 525\nfy: 525\ncx: 319.5\ncy: 239.5\nwidth: 640\nheight: 480\n";
  const Intrinsics k = parseIntrinsicsSpec((dir / "k.yaml").string());
  EXPECT_DOUBLE_EQ(k.cx, 319.5);
  EXPECT_EQ(k.height, 480);

  std::ofstream(dir / "typo.yaml") << "fx: 525\nfy: 525\ncx: 319.5\ncy: 239.5\nfocal: 3\n";
  EXPECT_THROW(parseIntrinsicsSpec((dir / "typo.yaml").string()), ConfigError);
  std::ofstream(dir / "short.yaml") << "fx: 525\nfy: 525\ncx: 319.5\n";
  try {
    parseIntrinsicsSpec((dir / "short.yaml").string());
    FAIL() << "expected an error for the missing cy";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("'cy'"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tessera::core
