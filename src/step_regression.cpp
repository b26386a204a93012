// Weighted least squares of the steps' ln values on time and foot (step_regression.hpp).
#include "step_regression.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace gaitmon::detail {

void check_steps(std::string_view who, std::span<const Foot> feet, std::span<const double> t_s,
                 std::span<const double> log_value, std::span<const double> variance) {
  const std::size_t n = t_s.size();
  if (log_value.size() != n || variance.size() != n || (!feet.empty() && feet.size() != n)) {
    throw std::invalid_argument(std::string(who) + ": " + std::to_string(feet.size()) + " feet, " +
                                std::to_string(n) + " times, " + std::to_string(log_value.size()) +
                                " values and " + std::to_string(variance.size()) + " variances");
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(t_s[i]) || !std::isfinite(log_value[i]) || !std::isfinite(variance[i]) ||
        !(variance[i] > 0.0)) {
      throw std::invalid_argument(std::string(who) + ": step " + std::to_string(i) +
                                  " has a time, value or variance that is not finite, or a "
                                  "variance that is not positive");
    }
  }
}

std::optional<StepRegression> regress_steps(std::span<const Foot> feet, std::span<const double> t_s,
                                            std::span<const double> log_value,
                                            std::span<const double> variance) {
  const std::size_t n = t_s.size();
  const bool by_foot = !feet.empty() && std::count(feet.begin(), feet.end(), Foot::Right) > 0 &&
                       std::count(feet.begin(), feet.end(), Foot::Left) > 0;
  const int parameters = by_foot ? 3 : 2;
  if (static_cast<int>(n) <= parameters) return std::nullopt;
  const auto right = [&](std::size_t i) { return by_foot && feet[i] == Foot::Right ? 1.0 : 0.0; };
  // Centred on the weighted means, the intercept decouples from the other two.
  double sw = 0.0, st = 0.0, sf = 0.0, sy = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double w = 1.0 / variance[i];
    sw += w;
    st += w * t_s[i] / 60.0;
    sf += w * right(i);
    sy += w * log_value[i];
  }
  const double t_mean = st / sw, f_mean = sf / sw, y_mean = sy / sw;
  const auto row = [&](std::size_t i) {
    return Eigen::Vector2d(t_s[i] / 60.0 - t_mean, right(i) - f_mean);
  };
  Eigen::Matrix2d normal = Eigen::Matrix2d::Zero();
  Eigen::Vector2d rhs = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d x = row(i);
    normal += x * x.transpose() / variance[i];
    rhs += x * (log_value[i] - y_mean) / variance[i];
  }
  if (!by_foot) normal(1, 1) = 1.0;  // the empty foot column, so that one solve serves both
  const Eigen::FullPivLU<Eigen::Matrix2d> lu(normal);
  if (!lu.isInvertible()) return std::nullopt;
  const Eigen::Vector2d beta = lu.solve(rhs);
  double chi2 = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double r = log_value[i] - y_mean - row(i).dot(beta);
    chi2 += r * r / variance[i];
  }
  const Eigen::Matrix2d covariance =
      chi2 / static_cast<double>(static_cast<int>(n) - parameters) * lu.inverse();
  StepRegression out;
  out.steps = static_cast<int>(n);
  out.centre_min = t_mean;
  out.ln_at_centre = y_mean;
  out.slope_per_min = beta[0];
  out.se_slope_per_min = std::sqrt(covariance(0, 0));
  out.by_foot = by_foot;
  if (by_foot) {
    out.right = beta[1];
    out.se_right = std::sqrt(covariance(1, 1));
  }
  return out;
}

}  // namespace gaitmon::detail
