#include <fstream>
#include <random>

#include <gtest/gtest.h>

#include "support/test_data.h"
#include "tessera/core/error.h"
#include "tessera/core/trajectory.h"
#include "tessera/eval/run_evaluation.h"

namespace tessera::eval {
namespace {

// A wavy ground-truth path at 30 Hz.
core::Trajectory groundTruth(int poses) {
  core::Trajectory gt;
  for (int i = 0; i < poses; ++i) {
    const double a = 0.05 * i;
    gt[1'000'000'000LL + i * 33'333'333LL] = core::isometryFromTranslationQuaternion(
        {std::cos(a), std::sin(a), 0.1 * a}, 0.0, 0.0, std::sin(a / 2), std::cos(a / 2));
  }
  return gt;
}

TEST(Ate, IsZeroForTheTruthSeenFromAnotherFrame) {
  const core::Trajectory gt = groundTruth(100);
  // The same path expressed in a frame rotated and shifted: alignment removes it exactly.
  core::Isometry T_other_gt = core::Isometry::Identity();
  T_other_gt.linear() =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  T_other_gt.translation() = Eigen::Vector3d(5, -2, 1);
  core::Trajectory estimate;
  for (const auto& [t, pose] : gt) estimate[t + 3'000'000] = T_other_gt * pose;  // 3 ms late
  const auto ate = core::absoluteTrajectoryError(estimate, gt);
  ASSERT_TRUE(ate.has_value());
  EXPECT_EQ(ate->pairs, 100u);
  EXPECT_LT(ate->rmse_m, 1e-9);
  EXPECT_TRUE(ate->T_gt_est.isApprox(T_other_gt.inverse(), 1e-9));
}

TEST(Ate, EqualsTheRmsOfKnownPositionErrors) {
  const core::Trajectory gt = groundTruth(400);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> angle(0.0, 2 * M_PI);
  core::Trajectory estimate;
  for (const auto& [t, pose] : gt) {
    // Each position off by exactly 2 cm in a random horizontal direction: RMSE 2 cm before
    // alignment; alignment can only lower it slightly.
    core::Isometry moved = pose;
    const double a = angle(rng);
    moved.translation() += 0.02 * Eigen::Vector3d(std::cos(a), std::sin(a), 0.0);
    estimate[t] = moved;
  }
  const auto ate = core::absoluteTrajectoryError(estimate, gt);
  ASSERT_TRUE(ate.has_value());
  EXPECT_NEAR(ate->rmse_m, 0.02, 0.002);
  EXPECT_LE(ate->max_m, 0.025);
}

TEST(Ate, NeedsThreeMatchedPoses) {
  const core::Trajectory gt = groundTruth(10);
  core::Trajectory far_off;
  for (const auto& [t, pose] : gt) far_off[t + 500'000'000] = pose;  // nothing within 20 ms
  EXPECT_FALSE(core::absoluteTrajectoryError(far_off, gt).has_value());
}

TEST(EvaluateRun, FillsAteIntoTheReportAndNamesMissingFiles) {
  const auto dir = test::freshTempDir();
  std::ofstream(dir / "report.json") << R"({"frames": 3, "ate_m": null})";
  std::ofstream(dir / "trajectory.txt") << "# t tx ty tz qx qy qz qw\n"
                                        << "1.000000000 0 0 0 0 0 0 1\n"
                                        << "1.033333000 0.1 0 0 0 0 0 1\n"
                                        << "1.066667000 0.2 0.1 0 0 0 0 1\n";
  std::ofstream(dir / "gt.json")
      << R"({"frames": [{"timestamp_ns": 1000000000, "T_W_C": [0,0,0,0,0,0,1]},
                         {"timestamp_ns": 1033333000, "T_W_C": [0.1,0,0,0,0,0,1]},
                         {"timestamp_ns": 1066667000, "T_W_C": [0.2,0.1,0,0,0,0,1]}]})";
  const nlohmann::json figures = evaluateRun(dir, dir / "gt.json");
  EXPECT_NEAR(figures["ate_m"].get<double>(), 0.0, 1e-9);
  EXPECT_EQ(figures["ate_pairs"], 3);
  std::ifstream report_file(dir / "report.json");
  const auto report = nlohmann::json::parse(report_file);
  EXPECT_EQ(report["frames"], 3);
  EXPECT_NEAR(report["ate_m"].get<double>(), 0.0, 1e-9);
  EXPECT_TRUE(report["plane_recall"].is_null());
  // The estimate aligned to the ground truth, in TUM format, reads back with the same poses.
  const core::Trajectory aligned = core::readTumTrajectory(dir / "trajectory_aligned.txt");
  ASSERT_EQ(aligned.size(), 3u);
  EXPECT_NEAR(aligned.rbegin()->second.translation().y(), 0.1, 1e-6);

  try {
    evaluateRun(dir / "missing_run", dir / "gt.json");
    FAIL() << "expected an error";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("missing_run"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tessera::eval
