// The paraboloid footprint fitted to a region's cell loads (see footprint.hpp for the derivation).
#include "gaitmon/footprint.hpp"

#include <Eigen/Core>
#include <Eigen/LU>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace gaitmon {
namespace {

constexpr int kTerms = 5;  // 1, u, v, u^2, v^2
constexpr double kMinAreaOfSensorArea = 0.5;
constexpr double kMaxAreaOfSensorArea = 2.0;
// Relative pivot below which the normal equations count as singular: far above rounding
// (~1e-16) and far below the weakest determinable layout (three rows, one cell in one of them).
constexpr double kRankThreshold = 1e-9;

}  // namespace

std::optional<double> footprint_area_mm2(std::span<const LoadedCell> cells, CellSize size) {
  if (!(size.width_mm > 0.0) || !(size.height_mm > 0.0) || !std::isfinite(size.width_mm) ||
      !std::isfinite(size.height_mm)) {
    throw std::invalid_argument("footprint_area_mm2: the cell size must be finite and positive");
  }
  if (cells.size() < static_cast<std::size_t>(kTerms)) return std::nullopt;
  // Centred and in cell units, so the normal equations are well conditioned.
  double mean_x = 0.0;
  double mean_y = 0.0;
  for (const LoadedCell& c : cells) {
    if (!std::isfinite(c.x_mm) || !std::isfinite(c.y_mm) || !std::isfinite(c.load)) {
      return std::nullopt;
    }
    mean_x += c.x_mm;
    mean_y += c.y_mm;
  }
  mean_x /= static_cast<double>(cells.size());
  mean_y /= static_cast<double>(cells.size());
  Eigen::Matrix<double, kTerms, kTerms> normal = Eigen::Matrix<double, kTerms, kTerms>::Zero();
  Eigen::Matrix<double, kTerms, 1> rhs = Eigen::Matrix<double, kTerms, 1>::Zero();
  for (const LoadedCell& c : cells) {
    const double u = (c.x_mm - mean_x) / size.width_mm;
    const double v = (c.y_mm - mean_y) / size.height_mm;
    const Eigen::Matrix<double, kTerms, 1> row(1.0, u, v, u * u, v * v);
    normal.noalias() += row * row.transpose();
    rhs += row * c.load;
  }
  Eigen::FullPivLU<Eigen::Matrix<double, kTerms, kTerms>> lu(normal);
  lu.setThreshold(kRankThreshold);
  if (lu.rank() < kTerms) return std::nullopt;
  const Eigen::Matrix<double, kTerms, 1> q = lu.solve(rhs);
  if (!(q(3) < 0.0) || !(q(4) < 0.0)) return std::nullopt;
  const double peak = q(0) - q(1) * q(1) / (4.0 * q(3)) - q(2) * q(2) / (4.0 * q(4));
  if (!(peak > 0.0)) return std::nullopt;
  // In cell units the ellipse's semi-axes are sqrt(-peak / q3) widths and sqrt(-peak / q4)
  // heights.
  const double area =
      std::numbers::pi * peak / std::sqrt(q(3) * q(4)) * size.width_mm * size.height_mm;
  const double sensor_area = static_cast<double>(cells.size()) * size.width_mm * size.height_mm;
  if (!(area >= kMinAreaOfSensorArea * sensor_area && area <= kMaxAreaOfSensorArea * sensor_area)) {
    return std::nullopt;
  }
  return area;
}

}  // namespace gaitmon
