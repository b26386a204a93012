// Left against right: does a region's tissue read stiffer or more damped under one foot than
// under the other (a hemiparetic or neuropathic foot, an old injury, or two insoles that differ)?
//
// Weighted least squares of each step's ln value on its foot (0 left, 1 right) and its
// heel-strike time, so that a drift over the session, which both feet share, neither passes for
// a difference between them nor widens it. As in drift.hpp the steps' fit variances are relative
// weights only and the standard error takes its scale from the residuals. The error that the
// measurement chain gives every step of a region alike (README, "How honest the standard errors
// are") cancels in the difference only as far as the two insoles mirror each other: what differs
// between them (each cell's dc offset, a calibration) reads as an asymmetry of the tissue and does
// not show in the steps' scatter. So a second, independent term for the pair of insoles is added
// to the standard error ([asymmetry] of the config, README "Left against right").
#pragma once

#include <optional>
#include <span>

#include "gaitmon/types.hpp"

namespace gaitmon {

/// Fewer steps of either foot than this give no comparison: three parameters and a scale need
/// some left over, and one foot's few steps would carry it alone.
inline constexpr int kMinAsymmetryStepsPerFoot = 3;

struct FootAsymmetry {
  int left_steps = 0;
  int right_steps = 0;
  double ln_ratio = 0.0;           ///< ln(right / left), at the same time
  double se_steps_ln_ratio = 0.0;  ///< its standard error from the steps' scatter
  double pair_sd_ln_ratio = 0.0;   ///< what the pair of insoles adds, as given
  double se_ln_ratio = 0.0;        ///< both together, root sum of squares
  /// How much higher the right foot's value is than the left's: 100 (right / left - 1).
  double pct = 0.0;
  double se_pct = 0.0;  ///< by the delta method from ln_ratio's standard error
  /// ln_ratio over its standard error; beyond about 3 the feet differ. Infinite (or 0 where the
  /// feet agree) where the steps fit the model exactly.
  double z() const;
};

/// The right foot's `log_value` against the left's, weighted by 1 / `variance`, with a linear
/// trend in `t_s` (seconds) shared by both feet; `pair_sd_ln_ratio` is the pair of insoles' own
/// SD of the log ratio. nullopt with fewer than kMinAsymmetryStepsPerFoot steps of either foot.
/// Throws std::invalid_argument if the lengths differ, a time or value is not finite, a variance
/// is not positive or the pair's SD is negative or not finite.
std::optional<FootAsymmetry> foot_asymmetry(std::span<const Foot> feet, std::span<const double> t_s,
                                            std::span<const double> log_value,
                                            std::span<const double> variance,
                                            double pair_sd_ln_ratio = 0.0);

}  // namespace gaitmon
