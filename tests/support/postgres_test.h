#pragma once
// A GoogleTest fixture with a throwaway PostgreSQL 15 (postgres_cluster.h) holding an empty
// database named kDatabase; the test is skipped, saying why, where PostgreSQL is not
// installed.

#include <gtest/gtest.h>

#include <memory>

#include "tests/support/postgres_cluster.h"

namespace linecal::testing_support {

class PostgresTest : public ::testing::Test {
 protected:
  static constexpr char kDatabase[] = "plant";

  void SetUp() override {
    if (std::string why = PostgresCluster::MissingReason(); !why.empty()) GTEST_SKIP() << why;
    absl::StatusOr<std::unique_ptr<PostgresCluster>> cluster = PostgresCluster::Create();
    ASSERT_TRUE(cluster.ok()) << cluster.status();
    cluster_ = *std::move(cluster);
    const absl::Status created = cluster_->CreateDatabase(kDatabase);
    ASSERT_TRUE(created.ok()) << created;
  }

  std::unique_ptr<PostgresCluster> cluster_;
};

}  // namespace linecal::testing_support
