// The regression under drift and asymmetry, against answers worked by hand: a line through
// three points, a foot offset that the time trend must not take up, and the cases without a fit.
#include "src/step_regression.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace gaitmon::detail {
namespace {

TEST(StepRegression, ThreeStepsGiveTheSlopeAndStandardErrorWorkedByHand) {
  // t = 0, 1, 2 min, ln values 0, 1, 1, equal weights. Centred t: -1, 0, 1; mean of y 2/3.
  // slope = sum (t - 1)(y - 2/3) / sum (t - 1)^2 = 1 / 2. Residuals -1/6, 1/3, -1/6, so
  // chi^2 = 1/6 on 3 - 2 = 1 degree of freedom, and var(slope) = (1/6) / 2 = 1/12.
  const std::vector<double> t_s{0.0, 60.0, 120.0};
  const std::vector<double> y{0.0, 1.0, 1.0};
  const std::vector<double> variance{1.0, 1.0, 1.0};
  const auto fit = regress_steps({}, t_s, y, variance);
  ASSERT_TRUE(fit.has_value());
  EXPECT_EQ(fit->steps, 3);
  EXPECT_FALSE(fit->by_foot);
  EXPECT_NEAR(fit->centre_min, 1.0, 1e-14);
  EXPECT_NEAR(fit->ln_at_centre, 2.0 / 3.0, 1e-14);
  EXPECT_NEAR(fit->slope_per_min, 0.5, 1e-14);
  EXPECT_NEAR(fit->se_slope_per_min, std::sqrt(1.0 / 12.0), 1e-14);
  EXPECT_EQ(fit->right, 0.0);
  EXPECT_EQ(fit->se_right, 0.0);
}

TEST(StepRegression, TheVariancesWeighOnlyRelativeToEachOther) {
  const std::vector<double> t_s{0.0, 30.0, 75.0, 140.0, 200.0};
  const std::vector<double> y{0.10, 0.31, 0.18, 0.52, 0.47};
  const std::vector<double> variance{1.0, 2.0, 0.5, 1.5, 3.0};
  std::vector<double> scaled = variance;
  for (double& v : scaled) v *= 250.0;
  const auto a = regress_steps({}, t_s, y, variance);
  const auto b = regress_steps({}, t_s, y, scaled);
  ASSERT_TRUE(a && b);
  EXPECT_NEAR(a->slope_per_min, b->slope_per_min, 1e-14);
  EXPECT_NEAR(a->se_slope_per_min, b->se_slope_per_min, 1e-14);
  EXPECT_GT(a->se_slope_per_min, 0.0);
}

TEST(StepRegression, AStepOfHalfTheVarianceWeighsAsTwoStepsInTheEstimate) {
  // Halving a step's variance doubles its weight: the estimate equals that of the same step
  // given twice (the standard errors differ: two steps add a degree of freedom).
  const std::vector<double> t_s{0.0, 40.0, 90.0, 150.0};
  const std::vector<double> y{0.2, 0.1, 0.45, 0.3};
  const auto halved = regress_steps({}, t_s, y, std::vector<double>{1.0, 1.0, 0.5, 1.0});
  const auto twice = regress_steps({}, std::vector<double>{0.0, 40.0, 90.0, 90.0, 150.0},
                                   std::vector<double>{0.2, 0.1, 0.45, 0.45, 0.3},
                                   std::vector<double>{1.0, 1.0, 1.0, 1.0, 1.0});
  ASSERT_TRUE(halved && twice);
  EXPECT_NEAR(halved->slope_per_min, twice->slope_per_min, 1e-14);
  EXPECT_NEAR(halved->ln_at_centre, twice->ln_at_centre, 1e-14);
  EXPECT_NEAR(halved->centre_min, twice->centre_min, 1e-14);
}

TEST(StepRegression, AFootOffsetIsFoundExactlyAndNotTakenForATrend) {
  // ln value = 0.3 + 0.05 t_min + 0.2 [right], without noise, the right foot's steps later in
  // the session on average: leaving the foot out would put part of 0.2 into the slope.
  std::vector<Foot> feet;
  std::vector<double> t_s, y;
  for (int i = 0; i < 12; ++i) {
    const Foot foot = i % 3 == 0 ? Foot::Left : Foot::Right;
    const double t = 10.0 * i + (foot == Foot::Right ? 25.0 : 0.0);
    feet.push_back(foot);
    t_s.push_back(t);
    y.push_back(0.3 + 0.05 * t / 60.0 + (foot == Foot::Right ? 0.2 : 0.0));
  }
  const std::vector<double> variance(feet.size(), 1.0);
  const auto fit = regress_steps(feet, t_s, y, variance);
  ASSERT_TRUE(fit.has_value());
  EXPECT_TRUE(fit->by_foot);
  EXPECT_NEAR(fit->slope_per_min, 0.05, 1e-12);
  EXPECT_NEAR(fit->right, 0.2, 1e-12);
  EXPECT_NEAR(fit->se_slope_per_min, 0.0, 1e-12);
  EXPECT_NEAR(fit->se_right, 0.0, 1e-12);

  const auto without_feet = regress_steps({}, t_s, y, variance);
  ASSERT_TRUE(without_feet.has_value());
  EXPECT_FALSE(without_feet->by_foot);
  EXPECT_GT(std::abs(without_feet->slope_per_min - 0.05), 0.01);
}

TEST(StepRegression, OneFootAloneHasNoFootTerm) {
  const std::vector<Foot> feet(4, Foot::Right);
  const std::vector<double> t_s{0.0, 60.0, 120.0, 180.0};
  const std::vector<double> y{1.0, 1.1, 1.2, 1.3};
  const auto fit = regress_steps(feet, t_s, y, std::vector<double>(4, 1.0));
  ASSERT_TRUE(fit.has_value());
  EXPECT_FALSE(fit->by_foot);
  EXPECT_NEAR(fit->slope_per_min, 0.1, 1e-12);
}

TEST(StepRegression, NoFitWithoutADegreeOfFreedomOrWhereTimeOrFootDoNotVary) {
  const std::vector<double> one(3, 1.0);
  // Two steps for two parameters.
  EXPECT_FALSE(regress_steps({}, std::vector<double>{0.0, 60.0}, std::vector<double>{0.0, 1.0},
                             std::vector<double>{1.0, 1.0}));
  // Three steps for three parameters once both feet are in.
  EXPECT_FALSE(regress_steps(std::vector<Foot>{Foot::Left, Foot::Right, Foot::Left},
                             std::vector<double>{0.0, 60.0, 120.0}, one, one));
  // Every step at the same time.
  EXPECT_FALSE(regress_steps({}, std::vector<double>{30.0, 30.0, 30.0},
                             std::vector<double>{0.0, 1.0, 2.0}, one));
  // The foot is the time: left steps all at 0 s, right steps all at 60 s.
  EXPECT_FALSE(regress_steps(std::vector<Foot>{Foot::Left, Foot::Left, Foot::Right, Foot::Right},
                             std::vector<double>{0.0, 0.0, 60.0, 60.0},
                             std::vector<double>{0.0, 0.1, 1.0, 1.1},
                             std::vector<double>{1.0, 1.0, 1.0, 1.0}));
}

TEST(StepRegression, CheckStepsNamesTheCallerAndTheFault) {
  const std::vector<double> three(3, 1.0);
  const std::vector<double> two(2, 1.0);
  const auto message = [](auto&& call) {
    try {
      call();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("(nothing thrown)");
  };
  EXPECT_NO_THROW(check_steps("drift", {}, three, three, three));
  EXPECT_EQ(message([&] { check_steps("drift", {}, three, two, three); }),
            "drift: 0 feet, 3 times, 2 values and 3 variances");
  EXPECT_EQ(message([&] {
              check_steps("asymmetry", std::vector<Foot>{Foot::Left}, three, three, three);
            }),
            "asymmetry: 1 feet, 3 times, 3 values and 3 variances");
  for (const double bad : {std::numeric_limits<double>::quiet_NaN(), 0.0, -1.0,
                           std::numeric_limits<double>::infinity()}) {
    std::vector<double> variance = three;
    variance[2] = bad;
    EXPECT_NE(message([&] { check_steps("drift", {}, three, three, variance); }).find("step 2 "),
              std::string::npos)
        << bad;
  }
  std::vector<double> y = three;
  y[0] = std::numeric_limits<double>::infinity();
  EXPECT_NE(message([&] { check_steps("drift", {}, three, y, three); }).find("drift: step 0 "),
            std::string::npos);
}

}  // namespace
}  // namespace gaitmon::detail
