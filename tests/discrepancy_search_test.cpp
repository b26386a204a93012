// The candidates' parameter search on objectives whose minimum and curvature are known in closed
// form: the pattern search follows an oblique valley and keeps to its box, and the settling
// takes the curvature at a minimum of the stencil's own scale, not on a slope; the clustered
// sandwich's errors worked by hand.
#include "src/discrepancy_search.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <vector>

namespace gaitmon::discrepancy_detail {
namespace {

// (theta - centre)' A (theta - centre), A = [[a, b], [b, c]]: cov = 2 H^-1 = A^-1.
struct Quadratic {
  double a, b, c;
  std::vector<double> centre;
  double operator()(const std::vector<double>& th) const {
    const double x = th[0] - centre[0];
    const double y = th[1] - centre[1];
    return a * x * x + 2 * b * x * y + c * y * y;
  }
  double se(std::size_t i) const {
    const double det = a * c - b * b;
    return std::sqrt((i == 0 ? c : a) / det);
  }
};

const SearchBox kWide{{-10.0, -10.0}, {10.0, 10.0}};

TEST(PatternSearch, FollowsAnObliqueValleyToItsFloor) {
  // Strength and tau trade off like this: the valley runs along (1, 1) and is 400 times
  // steeper across it.
  const Quadratic q{100.25, -99.75, 100.25, {0.6, 1.0}};
  int evaluations = 0;
  const SearchObjective f = [&](const std::vector<double>& th) {
    ++evaluations;
    return q(th);
  };
  const std::vector<double> start{0.3, 0.8};
  const SearchPoint end = pattern_search({start, f(start)}, {0.05, 0.05}, kWide, f);
  EXPECT_NEAR(end.theta[0], 0.6, 0.01);
  EXPECT_NEAR(end.theta[1], 1.0, 0.01);
  EXPECT_LT(end.value, 1e-3);
  EXPECT_LE(evaluations, 1 + 40 * 8 + 4 * 8);
}

TEST(PatternSearch, KeepsToItsBox) {
  const Quadratic q{1.0, 0.0, 1.0, {2.0, 0.5}};
  const SearchObjective f = [&](const std::vector<double>& th) {
    EXPECT_LE(th[0], 1.0);
    return q(th);
  };
  const SearchBox box{{0.0, 0.0}, {1.0, 1.0}};
  const SearchPoint end = pattern_search({{0.5, 0.5}, f({0.5, 0.5})}, {0.1, 0.1}, box, f);
  EXPECT_DOUBLE_EQ(end.theta[0], 1.0);
  EXPECT_NEAR(end.theta[1], 0.5, 1e-12);
}

TEST(SettleOnStencil, AtTheMinimumOfAQuadraticGivesItsCovarianceExactly) {
  const Quadratic q{400.0, -300.0, 250.0, {0.6, 1.0}};
  const SearchObjective f = [&](const std::vector<double>& th) { return q(th); };
  const SettledMinimum s = settle_on_stencil({q.centre, 0.0}, kWide, f);
  EXPECT_EQ(s.moves, 0);
  ASSERT_EQ(s.se.size(), 2u);
  // Central differences are exact on a quadratic; what is left is rounding.
  EXPECT_NEAR(s.se[0], q.se(0), 1e-9 * q.se(0));
  EXPECT_NEAR(s.se[1], q.se(1), 1e-9 * q.se(1));
  // cov = A^-1 = [[c, -b], [-b, a]] / (a c - b^2) = [[250, 300], [300, 400]] / 10000.
  ASSERT_EQ(s.cov.size(), 4u);
  EXPECT_NEAR(s.cov[0], 0.025, 1e-9);
  EXPECT_NEAR(s.cov[1], 0.03, 1e-9);
  EXPECT_NEAR(s.cov[2], 0.03, 1e-9);
  EXPECT_NEAR(s.cov[3], 0.04, 1e-9);
}

TEST(SettleOnStencil, OneParameter) {
  // D = (x - 2)^2 / 0.5: H = 4, cov = 2 / 4, SE = sqrt(0.5).
  const SearchObjective f = [](const std::vector<double>& th) {
    return (th[0] - 2.0) * (th[0] - 2.0) / 0.5;
  };
  const SettledMinimum s = settle_on_stencil({{2.0}, 0.0}, {{0.0}, {5.0}}, f);
  ASSERT_EQ(s.se.size(), 1u);
  EXPECT_NEAR(s.se[0], std::sqrt(0.5), 1e-9);
}

// A well -100 exp(-Q/2) of width sd in each parameter: near its floor the deviance is
// -100 + 50 Q, so H = 100/sd^2 and SE = sqrt(2/100) sd; more than sd from it the curvature is
// negative.
double well(const std::vector<double>& th) {
  constexpr double kSd = 0.08;
  const double x = (th[0] - 1.0) / kSd;
  const double y = (th[1] - 1.0) / kSd;
  return -100.0 * std::exp(-0.5 * (x * x + y * y));
}

TEST(SettleOnStencil, TakesTheCurvatureAtTheLowestPointOfItsStencilNotOnASlope) {
  const SearchObjective f = well;
  const std::vector<double> start{1.12, 0.94};
  // Where the search left it, 1.5 sd out along the first parameter, the stencil's curvature
  // there is negative: held to that point (a box of one point), no standard error comes out.
  const SettledMinimum held = settle_on_stencil({start, f(start)}, {start, start}, f);
  EXPECT_EQ(held.moves, 0);
  EXPECT_TRUE(std::isnan(held.se[0]));
  const SettledMinimum s = settle_on_stencil({start, f(start)}, kWide, f);
  EXPECT_GE(s.moves, 3);
  EXPECT_NEAR(s.at.theta[0], 1.0, 0.02);
  EXPECT_NEAR(s.at.theta[1], 1.0, 0.02);
  EXPECT_DOUBLE_EQ(s.at.value, f(s.at.theta));
  // The stencil's 3 % step is 0.4 sd and the centre within half a step of the floor: each costs
  // the curvature a few per cent.
  const double se = std::sqrt(2.0 / 100.0) * 0.08;
  for (double v : s.se) {
    ASSERT_TRUE(std::isfinite(v));
    EXPECT_NEAR(v, se, 0.1 * se);
  }
}

TEST(SettleOnStencil, MeasuresAFlatValleyOverTheStepWhereTheDevianceRises) {
  // A valley along (1, 1) whose floor rises by 0.02 over one stencil step, with ripples of 0.1
  // a tenth of a step apart: the kinks of the real profile. Over one step the ripples decide
  // the curvature along the floor; over the step where the deviance rises by 2 they are a few
  // per cent of it.
  const Quadratic q{5010.0, -4990.0, 5010.0, {1.0, 1.0}};
  const SearchObjective f = [&](const std::vector<double>& th) {
    return q(th) + 0.1 * std::sin(2 * std::numbers::pi * th[0] / 0.003) *
                       std::sin(2 * std::numbers::pi * th[1] / 0.003);
  };
  const SettledMinimum s = settle_on_stencil({q.centre, f(q.centre)}, kWide, f);
  EXPECT_EQ(s.moves, 0);
  for (std::size_t i = 0; i < 2; ++i) {
    ASSERT_TRUE(std::isfinite(s.se[i])) << i;
    EXPECT_NEAR(s.se[i], q.se(i), 0.1 * q.se(i)) << i;
  }
}

TEST(SettleOnStencil, NeverMovesOutOfItsBox) {
  // The minimum lies beyond the box's top in the first parameter: the stencil's point above is
  // lower but outside, so the centre stays on the bound (the workflow then gives no SE there).
  const Quadratic q{1.0, 0.0, 1.0, {2.0, 0.5}};
  int outside = 0;
  const SearchObjective f = [&](const std::vector<double>& th) {
    outside += th[0] > 1.0 ? 1 : 0;
    return q(th);
  };
  const SearchBox box{{0.0, 0.0}, {1.0, 1.0}};
  const SettledMinimum s = settle_on_stencil({{1.0, 0.5}, f({1.0, 0.5})}, box, f);
  EXPECT_EQ(s.moves, 0);
  EXPECT_EQ(s.at.theta, (std::vector<double>{1.0, 0.5}));
  EXPECT_GT(outside, 0);  // evaluated there for the curvature, not moved to
}

// model_cov = 2 H^-1, so H^-1 is half of it; B = G / (G - 1) sum_c d_c d_c'.
TEST(ClusteredSandwich, OneParameterByHand) {
  // H^-1 = 1. Clusters {1, -1} and {2, 0} sum to 0 and 2: B = 2 / 1 x 4 = 8, var = 8.
  const auto se = clustered_sandwich_se({2.0}, {{1.0}, {-1.0}, {2.0}, {0.0}}, {0, 0, 1, 1});
  ASSERT_EQ(se.size(), 1u);
  EXPECT_DOUBLE_EQ(se[0], std::sqrt(8.0));
  // Each unit its own cluster: B = 4 / 3 x (1 + 1 + 4) = 8 as well; the same four units as one
  // cluster give no error (one cluster cannot show a spread).
  EXPECT_DOUBLE_EQ(clustered_sandwich_se({2.0}, {{1.0}, {-1.0}, {2.0}, {0.0}}, {0, 1, 2, 3})[0],
                   std::sqrt(8.0));
  EXPECT_TRUE(std::isnan(clustered_sandwich_se({2.0}, {{1.0}, {2.0}}, {5, 5})[0]));
}

TEST(ClusteredSandwich, TwoParametersByHand) {
  // H^-1 = diag(1, 4). Three clusters (1, 0), (0, 1), (-1, -1): sum d d' = [[2, 1], [1, 2]],
  // B = 3 / 2 of it = [[3, 1.5], [1.5, 3]]; H^-1 B H^-1 = [[3, 6], [6, 48]].
  const auto se = clustered_sandwich_se({2.0, 0.0, 0.0, 8.0},
                                        {{1.0, 0.0}, {0.0, 1.0}, {-1.0, -1.0}}, {7, 8, 9});
  ASSERT_EQ(se.size(), 2u);
  EXPECT_NEAR(se[0], std::sqrt(3.0), 1e-12);
  EXPECT_NEAR(se[1], std::sqrt(48.0), 1e-12);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(std::isnan(clustered_sandwich_se({nan, nan, nan, nan}, {{1, 0}, {0, 1}}, {0, 1})[1]));
  EXPECT_THROW(clustered_sandwich_se({2.0, 0.0, 0.0}, {{1.0}}, {0}), std::invalid_argument);
  EXPECT_THROW(clustered_sandwich_se({2.0}, {{1.0}, {1.0}}, {0}), std::invalid_argument);
}

TEST(SettleOnStencil, RefusesThreeParameters) {
  const SearchObjective f = [](const std::vector<double>&) { return 0.0; };
  EXPECT_THROW(settle_on_stencil({{1.0, 1.0, 1.0}, 0.0}, {{0, 0, 0}, {2, 2, 2}}, f),
               std::invalid_argument);
}

}  // namespace
}  // namespace gaitmon::discrepancy_detail
