// JSON forms of the model's value types.
#include "gaitmon/json.hpp"

#include <gtest/gtest.h>

namespace gaitmon {
namespace {

TEST(Json, EllipsoidParamsCarryEveryParameterWithItsUnit) {
  const nlohmann::json j = EllipsoidParams{80.2, 80.7, 69.9, 16.4, 0.117, 0.294, 0.011, 1.18};
  EXPECT_EQ(j.size(), 8u);
  EXPECT_EQ(j.at("A_mm"), 80.2);
  EXPECT_EQ(j.at("B_mm"), 80.7);
  EXPECT_EQ(j.at("C_mm"), 69.9);
  EXPECT_EQ(j.at("d0_mm"), 16.4);
  EXPECT_EQ(j.at("kbar_n_per_mm3"), 0.117);
  EXPECT_EQ(j.at("n"), 0.294);
  EXPECT_EQ(j.at("cbar_ns_per_mm3"), 0.011);
  EXPECT_EQ(j.at("m"), 1.18);
}

// A region no step-region of which was fitted (a toe on the contact ellipse) had errors of 0,
// which read as a perfect fit.
TEST(Json, ARegionComparisonWithoutStepRegionsHasNoErrors) {
  const nlohmann::json fitted = RegionComparison{Region::Heel, 12, 1.5, 0.9};
  EXPECT_EQ(fitted.at("step_regions"), 12);
  EXPECT_EQ(fitted.at("baseline_heldout_nrmse_pct"), 1.5);
  EXPECT_EQ(fitted.at("extended_heldout_nrmse_pct"), 0.9);
  const nlohmann::json none = RegionComparison{Region::Toe2, 0, 0.0, 0.0};
  EXPECT_EQ(none.at("step_regions"), 0);
  EXPECT_TRUE(none.at("baseline_heldout_nrmse_pct").is_null());
  EXPECT_TRUE(none.at("extended_heldout_nrmse_pct").is_null());
}

}  // namespace
}  // namespace gaitmon
