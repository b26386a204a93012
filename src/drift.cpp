// A log parameter's trend over the session from the steps' regression (drift.hpp).
#include "gaitmon/drift.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "step_regression.hpp"

namespace gaitmon {

double LogTrend::z() const {
  if (se_ln_slope_per_min > 0.0) return ln_slope_per_min / se_ln_slope_per_min;
  if (ln_slope_per_min == 0.0) return 0.0;
  return std::copysign(std::numeric_limits<double>::infinity(), ln_slope_per_min);
}

double LogTrend::at(double t_s) const {
  return std::exp(ln_at_centre + ln_slope_per_min * (t_s - centre_s) / 60.0);
}

std::optional<LogTrend> log_trend(std::span<const double> t_s, std::span<const double> log_value,
                                  std::span<const double> variance, std::span<const Foot> feet) {
  detail::check_steps("log_trend", feet, t_s, log_value, variance);
  if (static_cast<int>(t_s.size()) < kMinTrendSteps) return std::nullopt;
  const auto [t_lo, t_hi] = std::minmax_element(t_s.begin(), t_s.end());
  if (!(*t_hi - *t_lo >= kMinTrendSpan_s)) return std::nullopt;
  const auto fit = detail::regress_steps(feet, t_s, log_value, variance);
  if (!fit) return std::nullopt;
  LogTrend trend;
  trend.steps = fit->steps;
  trend.span_min = (*t_hi - *t_lo) / 60.0;
  trend.centre_s = 60.0 * fit->centre_min;
  trend.ln_at_centre = fit->ln_at_centre;
  trend.ln_slope_per_min = fit->slope_per_min;
  trend.se_ln_slope_per_min = fit->se_slope_per_min;
  trend.pct_per_min = 100.0 * std::expm1(fit->slope_per_min);
  trend.se_pct_per_min = 100.0 * std::exp(fit->slope_per_min) * fit->se_slope_per_min;
  return trend;
}

}  // namespace gaitmon
