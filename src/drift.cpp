// Weighted least squares of a log parameter on time, its scale from the residuals (drift.hpp).
#include "gaitmon/drift.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

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
                                  std::span<const double> variance) {
  if (t_s.size() != log_value.size() || t_s.size() != variance.size()) {
    throw std::invalid_argument("log_trend: " + std::to_string(t_s.size()) + " times, " +
                                std::to_string(log_value.size()) + " values and " +
                                std::to_string(variance.size()) + " variances");
  }
  for (std::size_t i = 0; i < t_s.size(); ++i) {
    if (!std::isfinite(t_s[i]) || !std::isfinite(log_value[i]) || !std::isfinite(variance[i]) ||
        !(variance[i] > 0.0)) {
      throw std::invalid_argument("log_trend: step " + std::to_string(i) +
                                  " has a time, value or variance that is not finite, or a "
                                  "variance that is not positive");
    }
  }
  const auto n = static_cast<int>(t_s.size());
  if (n < kMinTrendSteps) return std::nullopt;
  const auto [t_lo, t_hi] = std::minmax_element(t_s.begin(), t_s.end());
  if (!(*t_hi - *t_lo >= kMinTrendSpan_s)) return std::nullopt;
  // Centred on the weighted mean time, the slope and intercept decouple.
  double sw = 0.0, swt = 0.0, swy = 0.0;
  for (std::size_t i = 0; i < t_s.size(); ++i) {
    const double w = 1.0 / variance[i];
    const double t = t_s[i] / 60.0;
    sw += w;
    swt += w * t;
    swy += w * log_value[i];
  }
  const double t_mean = swt / sw;
  const double y_mean = swy / sw;
  double stt = 0.0, sty = 0.0;
  for (std::size_t i = 0; i < t_s.size(); ++i) {
    const double w = 1.0 / variance[i];
    const double dt = t_s[i] / 60.0 - t_mean;
    stt += w * dt * dt;
    sty += w * dt * (log_value[i] - y_mean);
  }
  const double slope = sty / stt;
  double chi2 = 0.0;
  for (std::size_t i = 0; i < t_s.size(); ++i) {
    const double r = log_value[i] - y_mean - slope * (t_s[i] / 60.0 - t_mean);
    chi2 += r * r / variance[i];
  }
  const double se_slope = std::sqrt(chi2 / (n - 2) / stt);
  LogTrend trend;
  trend.steps = n;
  trend.span_min = (*t_hi - *t_lo) / 60.0;
  trend.centre_s = 60.0 * t_mean;
  trend.ln_at_centre = y_mean;
  trend.ln_slope_per_min = slope;
  trend.se_ln_slope_per_min = se_slope;
  trend.pct_per_min = 100.0 * std::expm1(slope);
  trend.se_pct_per_min = 100.0 * std::exp(slope) * se_slope;
  return trend;
}

}  // namespace gaitmon
