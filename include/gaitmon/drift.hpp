// A tissue parameter's trend over a session: does the heel stiffen or soften as the walk goes on
// (warming, fatigue, a sensor warming), or do the steps only scatter?
//
// Weighted least squares of each step's ln value on its heel-strike time (and, given the feet, a
// level for each foot, the model asymmetry.hpp shares). A step's fit gives the variance of its ln
// value (material_estimate), but those variances match how the steps scatter only up to a factor
// (README, "How honest the standard errors are": about right for ln kbar, about twice too large for
// ln cbar), and the tissue may also vary from step to step. So they are relative weights only: the
// slope's standard error takes its scale from the residuals about the line, chi^2 over the degrees
// of freedom left, as ordinary weighted regression does. An error shared by every step (the
// measurement chain's) moves the line, not its slope.
#pragma once

#include <optional>
#include <span>

#include "gaitmon/types.hpp"

namespace gaitmon {

/// Fewer steps than this give no trend: two parameters and a scale need some left over.
inline constexpr int kMinTrendSteps = 5;
/// Nor do steps spanning less than this: a change per minute from a few seconds of walking is
/// an extrapolation (the ten steps of a 6-s walk put a midfoot's cbar at -100 % a minute).
inline constexpr double kMinTrendSpan_s = 30.0;

struct LogTrend {
  int steps = 0;
  double span_min = 0.0;             ///< from the first step to the last
  double centre_s = 0.0;             ///< the steps' weighted mean time, where the line passes
  double ln_at_centre = 0.0;         ///< through the weighted mean of the ln values
  double ln_slope_per_min = 0.0;     ///< b, the slope of ln value per minute
  double se_ln_slope_per_min = 0.0;  ///< its standard error
  /// The change per minute, compounded: 100 (exp(b) - 1).
  double pct_per_min = 0.0;
  double se_pct_per_min = 0.0;  ///< by the delta method from b's standard error
  /// b over its standard error; beyond about 3 the data show a drift. Infinite (or 0 for a flat
  /// line) where the steps lie exactly on the line.
  double z() const;
  /// The fitted line at `t_s`, back on the value's own scale.
  double at(double t_s) const;
};

/// The trend of `log_value` (one per step) against `t_s` (the steps' times, seconds) weighted by
/// 1 / `variance`. With `feet` (one per step) each foot has its own level, so that a difference
/// between the feet (asymmetry.hpp) does not widen the trend's standard error; the line then
/// passes through the steps' weighted mean. nullopt with fewer than kMinTrendSteps steps or
/// spanning less than kMinTrendSpan_s.
/// Throws std::invalid_argument if the lengths differ, a value is not finite or a variance is
/// not positive.
std::optional<LogTrend> log_trend(std::span<const double> t_s, std::span<const double> log_value,
                                  std::span<const double> variance,
                                  std::span<const Foot> feet = {});

}  // namespace gaitmon
