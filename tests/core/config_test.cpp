#include <fstream>

#include <gtest/gtest.h>

#include "support/test_data.h"
#include "tessera/core/config.h"
#include "tessera/core/error.h"

namespace tessera::core {
namespace {

struct ExampleConfig {
  double size_m = 0.5;
  int count = 3;
  bool enabled = false;
  std::string name = "plain";
};

void readExample(const ConfigSection& section, ExampleConfig& config) {
  section.read("size_m", config.size_m);
  section.read("count", config.count);
  section.read("enabled", config.enabled);
  section.read("name", config.name);
}

// Runs `fn` and returns the ConfigError message it throws (fails the test if none).
template <typename Fn>
std::string configErrorOf(Fn fn) {
  try {
    fn();
  } catch (const ConfigError& e) {
    return e.what();
  }
  ADD_FAILURE() << "expected a ConfigError";
  return "";
}

TEST(Config, ReadsPresentKeysAndKeepsDefaultsForTheRest) {
  const auto doc =
      ConfigDocument::fromString("example:\n  size_m: 0.25\n  enabled: true\n", "test.yaml");
  ExampleConfig config;
  readExample(doc.root().section("example"), config);
  doc.checkAllKeysUsed();
  EXPECT_DOUBLE_EQ(config.size_m, 0.25);
  EXPECT_TRUE(config.enabled);
  EXPECT_EQ(config.count, 3);
  EXPECT_EQ(config.name, "plain");
}

TEST(Config, MisspelledKeyIsAnErrorNamingKeyAndFile) {
  const auto doc =
      ConfigDocument::fromString("example:\n  size_m: 0.25\n  cuont: 4\n", "office.yaml");
  ExampleConfig config;
  readExample(doc.root().section("example"), config);
  const std::string message = configErrorOf([&] { doc.checkAllKeysUsed(); });
  EXPECT_NE(message.find("office.yaml"), std::string::npos) << message;
  EXPECT_NE(message.find("example.cuont"), std::string::npos) << message;
}

TEST(Config, UnknownSectionIsAnError) {
  const auto doc = ConfigDocument::fromString("exmaple:\n  size_m: 0.25\n", "a.yaml");
  ExampleConfig config;
  readExample(doc.root().section("example"), config);
  const std::string message = configErrorOf([&] { doc.checkAllKeysUsed(); });
  EXPECT_NE(message.find("'exmaple'"), std::string::npos) << message;
}

TEST(Config, WrongTypeNamesKeyFileAndValue) {
  const auto doc = ConfigDocument::fromString("example:\n  count: many\n", "b.yaml");
  ExampleConfig config;
  const std::string message =
      configErrorOf([&] { readExample(doc.root().section("example"), config); });
  EXPECT_NE(message.find("b.yaml"), std::string::npos) << message;
  EXPECT_NE(message.find("example.count"), std::string::npos) << message;
  EXPECT_NE(message.find("many"), std::string::npos) << message;
}

TEST(Config, ScalarWhereASectionBelongsIsAnError) {
  const auto doc = ConfigDocument::fromString("example: 3\n", "c.yaml");
  const std::string message = configErrorOf([&] { doc.root().section("example"); });
  EXPECT_NE(message.find("c.yaml"), std::string::npos) << message;
}

TEST(Config, MissingFileAndBadYamlAreClearErrors) {
  const std::string missing =
      configErrorOf([] { ConfigDocument::load("/nonexistent/tessera.yaml"); });
  EXPECT_NE(missing.find("/nonexistent/tessera.yaml"), std::string::npos) << missing;

  const auto dir = test::freshTempDir();
  std::ofstream(dir / "broken.yaml") << "example: [unclosed\n";
  const std::string broken = configErrorOf([&] { ConfigDocument::load(dir / "broken.yaml"); });
  EXPECT_NE(broken.find("broken.yaml"), std::string::npos) << broken;
}

TEST(Config, ReportsKeysAskedForButAbsent) {
  const auto doc = ConfigDocument::fromString("example:\n  size_m: 1\n", "d.yaml");
  ExampleConfig config;
  readExample(doc.root().section("example"), config);
  const auto absent = doc.keysAskedButAbsent();
  EXPECT_EQ(absent, (std::vector<std::string>{"example.count", "example.enabled", "example.name"}));
}

TEST(Config, ReadsListsOfMapsAndNumbersAndChecksTheirKeys) {
  const auto doc = ConfigDocument::fromString(
      "planes:\n"
      "  - id: floor\n    polygon: [[0, 0], [4, 0], [4, 5]]\n    normal: [0, 0, 1]\n"
      "  - id: wall\n    polygon: [[0, 0], [1, 0], [1, 1]]\n    colour: red\n",
      "scene.yaml");
  const auto planes = doc.root().list("planes");
  ASSERT_EQ(planes.size(), 2u);
  std::string id;
  std::vector<std::vector<double>> polygon;
  std::vector<double> normal;
  planes[0].read("id", id);
  planes[0].read("polygon", polygon);
  planes[0].read("normal", normal);
  EXPECT_EQ(id, "floor");
  ASSERT_EQ(polygon.size(), 3u);
  EXPECT_DOUBLE_EQ(polygon[2][1], 5.0);
  EXPECT_EQ(normal, (std::vector<double>{0, 0, 1}));
  planes[1].read("id", id);
  planes[1].read("polygon", polygon);
  const std::string message = configErrorOf([&] { doc.checkAllKeysUsed(); });
  EXPECT_NE(message.find("planes[1].colour"), std::string::npos) << message;

  std::vector<double> bad;
  const auto typed = ConfigDocument::fromString("v: [1, x]\n", "t.yaml");
  EXPECT_NE(configErrorOf([&] { typed.root().read("v", bad); }).find("list of numbers"),
            std::string::npos);
}

}  // namespace
}  // namespace tessera::core
