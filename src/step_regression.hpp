// The regression behind a parameter's drift over a session (drift.hpp) and its difference between
// the feet (asymmetry.hpp): weighted least squares of each step's ln value on its time and its
// foot, the scale taken from the residuals. One model for both, so that neither passes for the
// other or widens the other's standard error. Internal: not part of the public API.
#pragma once

#include <optional>
#include <span>
#include <string_view>

#include "gaitmon/types.hpp"

namespace gaitmon::detail {

struct StepRegression {
  int steps = 0;
  double centre_min = 0.0;     ///< the steps' weighted mean time, minutes
  double ln_at_centre = 0.0;   ///< the weighted mean of the ln values, where the fit passes
  double slope_per_min = 0.0;  ///< of the ln value on time
  double se_slope_per_min = 0.0;
  bool by_foot = false;  ///< whether the right foot's offset is in the model
  double right = 0.0;    ///< ln(right / left) at the same time
  double se_right = 0.0;
};

/// Throws std::invalid_argument, naming `who`, unless the spans are alike in length (`feet` may
/// also be empty) and every time and value is finite and every variance positive and finite.
void check_steps(std::string_view who, std::span<const Foot> feet, std::span<const double> t_s,
                 std::span<const double> log_value, std::span<const double> variance);

/// log_value ~ intercept + slope t + right [foot is right], weighted by 1 / variance, the right
/// foot's term only where `feet` is given and holds both feet. The standard errors scale the
/// variances by chi^2 / (steps - parameters), so the variances act as relative weights only.
/// nullopt without a degree of freedom left or where the times (or the feet) do not vary.
std::optional<StepRegression> regress_steps(std::span<const Foot> feet, std::span<const double> t_s,
                                            std::span<const double> log_value,
                                            std::span<const double> variance);

}  // namespace gaitmon::detail
