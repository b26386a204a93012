// A log parameter's trend over a session: a hand-worked case, the weights' scale, calibration of
// the standard error on many noisy sessions, and misuse.
#include "gaitmon/drift.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

namespace gaitmon {
namespace {

// Five steps a minute apart, equal weights, ln values 0, 0.1, 0.1, 0.3, 0.4. By hand: centred
// times -2..2 min, sum of squares 10, centred cross products 1.0, so the slope is 0.1 per minute;
// the residuals 0.02, 0.02, -0.08, 0.02, 0.02 leave 0.008, so the slope's standard error is
// sqrt(0.008 / 3 / 10) = 0.016330. In per cent compounded: 100 (e^0.1 - 1) = 10.517 and
// 100 e^0.1 0.016330 = 1.80474. The variances are weights only: scaling them all changes nothing.
TEST(Drift, MatchesAHandWorkedCase) {
  const std::vector<double> t{0.0, 60.0, 120.0, 180.0, 240.0};
  const std::vector<double> y{0.0, 0.1, 0.1, 0.3, 0.4};
  for (double v : {1.0, 4.0, 1e-4}) {
    const auto trend = log_trend(t, y, std::vector<double>(5, v));
    ASSERT_TRUE(trend) << v;
    EXPECT_EQ(trend->steps, 5);
    EXPECT_DOUBLE_EQ(trend->span_min, 4.0);
    EXPECT_NEAR(trend->pct_per_min, 10.517092, 1e-6) << v;
    EXPECT_NEAR(trend->se_pct_per_min, 1.804737, 1e-5) << v;
    EXPECT_NEAR(trend->ln_slope_per_min, 0.1, 1e-12) << v;
    EXPECT_NEAR(trend->se_ln_slope_per_min, 0.0163299, 1e-7) << v;
    EXPECT_NEAR(trend->z(), 0.1 / 0.0163299, 1e-4) << v;
    // Through the means (2 min, 0.18): at 4 min ln 0.38, at 0 min ln -0.02.
    EXPECT_NEAR(trend->at(240.0), std::exp(0.38), 1e-12) << v;
    EXPECT_NEAR(trend->at(0.0), std::exp(-0.02), 1e-12) << v;
  }
}

// Weights follow the variances: a step given a huge variance hardly moves the line, so an
// outlier with it is ignored, and with the others' variance it pulls the slope.
TEST(Drift, AStepWithALargeVarianceHardlyCounts) {
  const std::vector<double> t{0.0, 60.0, 120.0, 180.0, 240.0, 300.0};
  const std::vector<double> y{0.0, 0.05, 0.1, 0.15, 0.2, 5.0};
  const auto ignored = log_trend(t, y, std::vector<double>{1, 1, 1, 1, 1, 1e12});
  const auto pulled = log_trend(t, y, std::vector<double>(6, 1.0));
  ASSERT_TRUE(ignored && pulled);
  EXPECT_NEAR(ignored->pct_per_min, 100.0 * std::expm1(0.05), 1e-3);
  EXPECT_GT(pulled->pct_per_min, 50.0);
}

// Steps on an exact line have a slope without scatter; on a flat one, no drift at all.
TEST(Drift, AnExactLineHasNoStandardError) {
  std::vector<double> t, y;
  for (int i = 0; i < 8; ++i) {
    t.push_back(30.0 * i);
    y.push_back(-1.0 + std::log(0.95) * (30.0 * i / 60.0));
  }
  const auto trend = log_trend(t, y, std::vector<double>(8, 0.01));
  ASSERT_TRUE(trend);
  EXPECT_NEAR(trend->pct_per_min, -5.0, 1e-9);
  EXPECT_NEAR(trend->se_pct_per_min, 0.0, 1e-9);
  EXPECT_LT(trend->z(), -1e6);
  const auto flat = log_trend(t, std::vector<double>(8, 0.5), std::vector<double>(8, 0.01));
  ASSERT_TRUE(flat);
  EXPECT_EQ(flat->pct_per_min, 0.0);
  EXPECT_EQ(flat->se_pct_per_min, 0.0);
  EXPECT_EQ(flat->z(), 0.0);
}

// 2000 sessions of 40 steps over 10 minutes, a true drift of -3 % a minute, each step's noise SD
// its own (0.02-0.10), but twice what its variance says (as a fit's may be off by a factor): the
// estimates centre on the truth, and their z against it scatter with SD 1 and 95 % within 1.96.
TEST(Drift, TheStandardErrorMatchesTheScatterWhateverTheVariancesScale) {
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> sd_of(0.02, 0.10);
  std::normal_distribution<double> unit;
  const double slope = std::log(0.97);
  double sum = 0.0, sum_z2 = 0.0;
  int within = 0;
  const int sessions = 2000;
  for (int s = 0; s < sessions; ++s) {
    std::vector<double> t, y, v;
    for (int i = 0; i < 40; ++i) {
      const double sd = sd_of(rng);
      t.push_back(15.0 * i);
      y.push_back(0.5 + slope * (15.0 * i / 60.0) + 2.0 * sd * unit(rng));
      v.push_back(sd * sd);
    }
    const auto trend = log_trend(t, y, v);
    ASSERT_TRUE(trend);
    const double z = (trend->pct_per_min + 3.0) / trend->se_pct_per_min;
    sum += trend->pct_per_min;
    sum_z2 += z * z;
    within += std::abs(z) < 1.96 ? 1 : 0;
  }
  EXPECT_NEAR(sum / sessions, -3.0, 0.05);
  EXPECT_NEAR(std::sqrt(sum_z2 / sessions), 1.0, 0.06);
  EXPECT_NEAR(static_cast<double>(within) / sessions, 0.95, 0.015);
}

// Given the feet, each has its own level: steps on one exact line per foot, the right foot 10 %
// higher, have the line's slope without scatter; without the feet the difference between them is
// scatter about one line, and the slope's standard error grows with it.
TEST(Drift, EachFootHasItsOwnLevelWhenTheFeetAreGiven) {
  std::vector<Foot> feet;
  std::vector<double> t, y;
  for (int i = 0; i < 12; ++i) {
    feet.push_back(i % 2 == 0 ? Foot::Left : Foot::Right);
    t.push_back(5.0 * i);
    y.push_back((feet.back() == Foot::Right ? std::log(1.1) : 0.0) +
                std::log(0.95) * t.back() / 60.0);
  }
  const std::vector<double> v(12, 0.01);
  const auto by_foot = log_trend(t, y, v, feet);
  const auto one_line = log_trend(t, y, v);
  ASSERT_TRUE(by_foot && one_line);
  EXPECT_NEAR(by_foot->pct_per_min, -5.0, 1e-9);
  EXPECT_NEAR(by_foot->se_pct_per_min, 0.0, 1e-9);
  EXPECT_GT(one_line->se_pct_per_min, 1.0);
  EXPECT_THROW(log_trend(t, y, v, std::vector<Foot>(11, Foot::Left)), std::invalid_argument);
}

// Four steps, or steps within less than 30 s, give no trend; 30 s of steps give one.
TEST(Drift, TooFewStepsOrTooShortASpanGiveNoTrend) {
  const std::vector<double> y{0, 1, 2, 3, 4, 5};
  EXPECT_FALSE(log_trend(std::vector<double>{0, 60, 120, 180}, std::vector<double>{0, 1, 2, 3},
                         std::vector<double>(4, 1.0)));
  EXPECT_FALSE(log_trend(std::vector<double>(6, 10.0), y, std::vector<double>(6, 1.0)));
  EXPECT_FALSE(
      log_trend(std::vector<double>{0, 5, 10, 15, 20, 29.9}, y, std::vector<double>(6, 1.0)));
  EXPECT_TRUE(log_trend(std::vector<double>{0, 5, 10, 15, 20, 30}, y, std::vector<double>(6, 1.0)));
}

TEST(Drift, RejectsMismatchedOrBadInput) {
  const std::vector<double> five{0, 1, 2, 3, 4};
  EXPECT_THROW(log_trend(five, std::vector<double>{0, 1, 2, 3}, five), std::invalid_argument);
  EXPECT_THROW(
      log_trend(five, std::vector<double>{0, 1, std::nan(""), 3, 4}, std::vector<double>(5, 1.0)),
      std::invalid_argument);
  EXPECT_THROW(log_trend(five, five, std::vector<double>{1, 1, 0, 1, 1}), std::invalid_argument);
  EXPECT_THROW(log_trend(five, five, std::vector<double>{1, 1, -1, 1, 1}), std::invalid_argument);
}

}  // namespace
}  // namespace gaitmon
