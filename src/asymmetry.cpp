// Right against left from the steps' regression on foot and time (asymmetry.hpp).
#include "gaitmon/asymmetry.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "step_regression.hpp"

namespace gaitmon {

double FootAsymmetry::z() const {
  if (se_ln_ratio > 0.0) return ln_ratio / se_ln_ratio;
  if (ln_ratio == 0.0) return 0.0;
  return std::copysign(std::numeric_limits<double>::infinity(), ln_ratio);
}

std::optional<FootAsymmetry> foot_asymmetry(std::span<const Foot> feet, std::span<const double> t_s,
                                            std::span<const double> log_value,
                                            std::span<const double> variance,
                                            double pair_sd_ln_ratio) {
  if (feet.size() != t_s.size()) {
    throw std::invalid_argument("foot_asymmetry: " + std::to_string(feet.size()) + " feet and " +
                                std::to_string(t_s.size()) + " times");
  }
  detail::check_steps("foot_asymmetry", feet, t_s, log_value, variance);
  if (!(std::isfinite(pair_sd_ln_ratio) && pair_sd_ln_ratio >= 0.0)) {
    throw std::invalid_argument("foot_asymmetry: the pair's SD must be finite and >= 0, got " +
                                std::to_string(pair_sd_ln_ratio));
  }
  FootAsymmetry out;
  out.right_steps = static_cast<int>(std::count(feet.begin(), feet.end(), Foot::Right));
  out.left_steps = static_cast<int>(feet.size()) - out.right_steps;
  if (out.left_steps < kMinAsymmetryStepsPerFoot || out.right_steps < kMinAsymmetryStepsPerFoot) {
    return std::nullopt;
  }
  const auto fit = detail::regress_steps(feet, t_s, log_value, variance);
  if (!fit) return std::nullopt;
  out.ln_ratio = fit->right;
  out.se_steps_ln_ratio = fit->se_right;
  out.pair_sd_ln_ratio = pair_sd_ln_ratio;
  out.se_ln_ratio = std::hypot(out.se_steps_ln_ratio, pair_sd_ln_ratio);
  out.pct = 100.0 * std::expm1(out.ln_ratio);
  out.se_pct = 100.0 * std::exp(out.ln_ratio) * out.se_ln_ratio;
  return out;
}

}  // namespace gaitmon
