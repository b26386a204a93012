// The right foot against the left: a hand-worked case, a drift both feet share, calibration of
// the standard error on many noisy sessions, and misuse.
#include "gaitmon/asymmetry.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

namespace gaitmon {
namespace {

constexpr Foot L = Foot::Left;
constexpr Foot R = Foot::Right;

// Three steps a foot at the same times, equal weights, ln values 0, 0.1, 0 (left) and 0.3, 0.2,
// 0.3 (right). By hand: the design is balanced, so the time term is 0 and orthogonal to the foot,
// and the log ratio is the difference of the means, 0.26667 - 0.03333 = 0.23333. The residuals
// -1/30, 2/30, -1/30 about each mean leave chi^2 = 0.013333 over 6 - 3 degrees of freedom, so
// the variance of the difference is 0.0044444 (1/3 + 1/3) and its standard error 0.054433. In
// per cent: 100 (e^0.23333 - 1) = 26.2802 and 100 e^0.23333 0.054433 = 6.87383. The variances
// are weights only: scaling them all changes nothing.
TEST(Asymmetry, MatchesAHandWorkedCase) {
  const std::vector<Foot> feet{L, L, L, R, R, R};
  const std::vector<double> t{0.0, 60.0, 120.0, 0.0, 60.0, 120.0};
  const std::vector<double> y{0.0, 0.1, 0.0, 0.3, 0.2, 0.3};
  for (double v : {1.0, 4.0, 1e-4}) {
    const auto a = foot_asymmetry(feet, t, y, std::vector<double>(6, v));
    ASSERT_TRUE(a) << v;
    EXPECT_EQ(a->left_steps, 3);
    EXPECT_EQ(a->right_steps, 3);
    EXPECT_NEAR(a->ln_ratio, 0.233333, 1e-6) << v;
    EXPECT_NEAR(a->se_ln_ratio, 0.0544331, 1e-7) << v;
    EXPECT_NEAR(a->pct, 26.28023, 1e-5) << v;
    EXPECT_NEAR(a->se_pct, 6.87383, 1e-5) << v;
    EXPECT_NEAR(a->z(), 4.28661, 1e-5) << v;
  }
}

// The right foot lands half a stride after the left, so under a drift both feet share its steps
// are each a little further along: compared without the time, the right foot would read 5 % lower
// here (half a minute at -10 % a minute). With it there is no difference, however steep the drift.
TEST(Asymmetry, ADriftBothFeetShareIsNoDifferenceBetweenThem) {
  std::vector<Foot> feet;
  std::vector<double> t, y;
  for (int i = 0; i < 6; ++i) {
    for (Foot f : {L, R}) {
      feet.push_back(f);
      t.push_back(60.0 * i + (f == R ? 30.0 : 0.0));
      y.push_back(0.2 + std::log(0.9) * t.back() / 60.0);
    }
  }
  const auto a = foot_asymmetry(feet, t, y, std::vector<double>(12, 0.01));
  ASSERT_TRUE(a);
  EXPECT_NEAR(a->ln_ratio, 0.0, 1e-12);
  EXPECT_NEAR(a->pct, 0.0, 1e-10);
}

// 2000 sessions of 30 steps a foot over 60 s, the right foot 10 % higher, a drift of -5 % a
// minute, each step's noise SD its own (0.02-0.10) but twice what its variance says: the estimates
// centre on the truth, and their z against it scatter with SD 1 and 95 % within 1.96.
TEST(Asymmetry, TheStandardErrorMatchesTheScatterWhateverTheVariancesScale) {
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> sd_of(0.02, 0.10);
  std::normal_distribution<double> unit;
  const double ratio = std::log(1.1);
  double sum = 0.0, sum_z2 = 0.0;
  int within = 0;
  const int sessions = 2000;
  for (int s = 0; s < sessions; ++s) {
    std::vector<Foot> feet;
    std::vector<double> t, y, v;
    for (int i = 0; i < 60; ++i) {
      const double sd = sd_of(rng);
      feet.push_back(i % 2 == 0 ? L : R);
      t.push_back(1.0 * i);
      y.push_back(-1.0 + (feet.back() == R ? ratio : 0.0) + std::log(0.95) * t.back() / 60.0 +
                  2.0 * sd * unit(rng));
      v.push_back(sd * sd);
    }
    const auto a = foot_asymmetry(feet, t, y, v);
    ASSERT_TRUE(a);
    const double z = (a->ln_ratio - ratio) / a->se_ln_ratio;
    sum += a->pct;
    sum_z2 += z * z;
    within += std::abs(z) < 1.96 ? 1 : 0;
  }
  EXPECT_NEAR(sum / sessions, 10.0, 0.1);
  EXPECT_NEAR(std::sqrt(sum_z2 / sessions), 1.0, 0.06);
  EXPECT_NEAR(static_cast<double>(within) / sessions, 0.95, 0.015);
}

// Fewer than three steps of either foot compare nothing; three of each do.
TEST(Asymmetry, TooFewStepsOfAFootGiveNoComparison) {
  const std::vector<double> t{0, 1, 2, 3, 4, 5, 6};
  const std::vector<double> y{0, 1, 0, 1, 0, 1, 0};
  const std::vector<double> v(7, 1.0);
  EXPECT_FALSE(foot_asymmetry(std::vector<Foot>{L, R, L, R, L, L, L}, t, y, v));
  EXPECT_FALSE(foot_asymmetry(std::vector<Foot>(7, R), t, y, v));
  const auto a = foot_asymmetry(std::vector<Foot>{L, R, L, R, L, R, L}, t, y, v);
  ASSERT_TRUE(a);
  EXPECT_EQ(a->left_steps, 4);
  EXPECT_EQ(a->right_steps, 3);
}

TEST(Asymmetry, RejectsMismatchedOrBadInput) {
  const std::vector<Foot> feet{L, R, L, R, L, R};
  const std::vector<double> six{0, 1, 2, 3, 4, 5};
  const std::vector<double> ones(6, 1.0);
  EXPECT_THROW(foot_asymmetry(feet, std::vector<double>{0, 1, 2}, six, ones),
               std::invalid_argument);
  EXPECT_THROW(foot_asymmetry(feet, six, std::vector<double>{0, 1, std::nan(""), 3, 4, 5}, ones),
               std::invalid_argument);
  EXPECT_THROW(foot_asymmetry(feet, six, six, std::vector<double>{1, 1, 0, 1, 1, 1}),
               std::invalid_argument);
  EXPECT_THROW(foot_asymmetry(feet, std::vector<double>{0, 1, 2, INFINITY, 4, 5}, six, ones),
               std::invalid_argument);
}

}  // namespace
}  // namespace gaitmon
