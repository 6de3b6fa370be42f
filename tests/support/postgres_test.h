#pragma once
// The GoogleTest fixture over a throwaway PostgreSQL server (postgres_cluster.h).
#include <cstdlib>
#include <string>

#include <gtest/gtest.h>

#include "support/postgres_cluster.h"

namespace tessera::test {

// A test suite sharing one throwaway server (starting one takes a second or two); each test
// skips with the reason when none could start, and gets a fresh database from freshDatabase().
// The password reaches libpq as it would on a robot: through PGPASSWORD.
class PostgresTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    cluster_ = PostgresCluster::start(why_not_).release();
    if (cluster_ != nullptr) setenv("PGPASSWORD", PostgresCluster::password(), 1);
  }
  static void TearDownTestSuite() {
    delete cluster_;
    cluster_ = nullptr;
  }
  void SetUp() override {
    if (cluster_ == nullptr) GTEST_SKIP() << why_not_;
  }
  static std::string freshDatabase() {
    static int counter = 0;
    const std::string name = "t" + std::to_string(++counter);
    EXPECT_TRUE(cluster_->createDatabase(name));
    return cluster_->url(name);
  }

  static inline PostgresCluster* cluster_ = nullptr;
  static inline std::string why_not_;
};

}  // namespace tessera::test
