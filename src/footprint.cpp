// The paraboloid footprint fitted to a region's cell loads (see footprint.hpp for the derivation).
#include "gaitmon/footprint.hpp"

#include <Eigen/Core>
#include <Eigen/LU>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <vector>

namespace gaitmon {
namespace {

constexpr double kMinAreaOfSensorArea = 0.5;
constexpr double kMaxAreaOfSensorArea = 2.0;
// A cell whose centre the footprint covers reads; well inside the rim (a quarter of the peak
// pressure is 87 % of the way out) a reading of nothing means the fit is wrong, not the cell.
constexpr double kMaxUnloadedPressureOfPeak = 0.25;
// Relative pivot below which the normal equations count as singular: far above rounding
// (~1e-16) and far below the weakest determinable layout (three rows, one cell in one of them).
constexpr double kRankThreshold = 1e-9;

/// p = q0 + q1 u + q2 v + q3 u^2 + q4 v^2 in cell units (u widths, v heights from the centroid).
struct Quadratic {
  double q0, q1, q2, q3, q4;
};

/// Least squares of the cells' loads on `Terms` functions of (u, v); nullopt if the cells do
/// not determine them.
template <int Terms, typename RowOf>
std::optional<Eigen::Matrix<double, Terms, 1>> least_squares(std::span<const LoadedCell> cells,
                                                             double mean_x, double mean_y,
                                                             CellSize size, RowOf row_of) {
  if (cells.size() < static_cast<std::size_t>(Terms)) return std::nullopt;
  Eigen::Matrix<double, Terms, Terms> normal = Eigen::Matrix<double, Terms, Terms>::Zero();
  Eigen::Matrix<double, Terms, 1> rhs = Eigen::Matrix<double, Terms, 1>::Zero();
  for (const LoadedCell& c : cells) {
    const Eigen::Matrix<double, Terms, 1> row =
        row_of((c.x_mm - mean_x) / size.width_mm, (c.y_mm - mean_y) / size.height_mm);
    normal.noalias() += row * row.transpose();
    rhs += row * c.load;
  }
  Eigen::FullPivLU<Eigen::Matrix<double, Terms, Terms>> lu(normal);
  lu.setThreshold(kRankThreshold);
  if (lu.rank() < Terms) return std::nullopt;
  return lu.solve(rhs);
}

/// The cap's area, or nullopt if the quadratic is not a cap, the area is implausible, or the cap
/// covers the centre of a cell that reads nothing.
std::optional<double> cap_area_mm2(const Quadratic& q, std::size_t cells,
                                   std::span<const CellCentre> unloaded, double mean_x,
                                   double mean_y, CellSize size) {
  if (!(q.q3 < 0.0) || !(q.q4 < 0.0)) return std::nullopt;
  const double peak = q.q0 - q.q1 * q.q1 / (4.0 * q.q3) - q.q2 * q.q2 / (4.0 * q.q4);
  if (!(peak > 0.0)) return std::nullopt;
  // In cell units the ellipse's semi-axes are sqrt(-peak / q3) widths and sqrt(-peak / q4)
  // heights.
  const double area =
      std::numbers::pi * peak / std::sqrt(q.q3 * q.q4) * size.width_mm * size.height_mm;
  const double sensor_area = static_cast<double>(cells) * size.width_mm * size.height_mm;
  if (!(area >= kMinAreaOfSensorArea * sensor_area && area <= kMaxAreaOfSensorArea * sensor_area)) {
    return std::nullopt;
  }
  for (const CellCentre& c : unloaded) {
    const double u = (c.x_mm - mean_x) / size.width_mm;
    const double v = (c.y_mm - mean_y) / size.height_mm;
    const double p = q.q0 + q.q1 * u + q.q2 * v + q.q3 * u * u + q.q4 * v * v;
    if (p > kMaxUnloadedPressureOfPeak * peak) return std::nullopt;
  }
  return area;
}

void require_cell_size(CellSize size) {
  if (!(size.width_mm > 0.0) || !(size.height_mm > 0.0) || !std::isfinite(size.width_mm) ||
      !std::isfinite(size.height_mm)) {
    throw std::invalid_argument("footprint: the cell size must be finite and positive");
  }
}

/// The cells' centroid, or nullopt if a cell is not finite or there is none. The fits work about
/// it and in cell units, so their normal equations are well conditioned.
std::optional<std::pair<double, double>> centroid(std::span<const LoadedCell> cells) {
  if (cells.empty()) return std::nullopt;
  double mean_x = 0.0;
  double mean_y = 0.0;
  for (const LoadedCell& c : cells) {
    if (!std::isfinite(c.x_mm) || !std::isfinite(c.y_mm) || !std::isfinite(c.load)) {
      return std::nullopt;
    }
    mean_x += c.x_mm;
    mean_y += c.y_mm;
  }
  const auto count = static_cast<double>(cells.size());
  return std::pair{mean_x / count, mean_y / count};
}

std::optional<Footprint> free_fit(std::span<const LoadedCell> cells, CellSize size,
                                  std::span<const CellCentre> unloaded) {
  const auto mean = centroid(cells);
  if (!mean) return std::nullopt;
  const auto [mean_x, mean_y] = *mean;
  using Row5 = Eigen::Matrix<double, 5, 1>;
  const auto q = least_squares<5>(cells, mean_x, mean_y, size,
                                  [](double u, double v) { return Row5(1.0, u, v, u * u, v * v); });
  if (!q) return std::nullopt;
  const Quadratic cap{(*q)(0), (*q)(1), (*q)(2), (*q)(3), (*q)(4)};
  const auto area = cap_area_mm2(cap, cells.size(), unloaded, mean_x, mean_y, size);
  if (!area) return std::nullopt;
  // rA^2 = -peak / q3 widths^2 and rB^2 = -peak / q4 heights^2.
  const double aspect = std::sqrt(cap.q4 / cap.q3) * size.width_mm / size.height_mm;
  const double peak = cap.q0 - cap.q1 * cap.q1 / (4.0 * cap.q3) - cap.q2 * cap.q2 / (4.0 * cap.q4);
  return Footprint{*area, aspect, peak};
}

// The four-term fit's cap at `aspect`, and the centroid it is written about.
struct CapFit {
  Quadratic cap;
  double mean_x, mean_y;
};

std::optional<CapFit> cap_at_aspect(std::span<const LoadedCell> cells, CellSize size,
                                    double aspect) {
  const auto mean = centroid(cells);
  if (!mean) return std::nullopt;
  const auto [mean_x, mean_y] = *mean;
  // rA = aspect rB, so in cell units q4 = kappa q3 with kappa = (aspect h / w)^2.
  const double ratio = aspect * size.height_mm / size.width_mm;
  const double kappa = ratio * ratio;
  using Row4 = Eigen::Matrix<double, 4, 1>;
  const auto q = least_squares<4>(cells, mean_x, mean_y, size, [kappa](double u, double v) {
    return Row4(1.0, u, v, u * u + kappa * v * v);
  });
  if (!q) return std::nullopt;
  return CapFit{{(*q)(0), (*q)(1), (*q)(2), (*q)(3), kappa * (*q)(3)}, mean_x, mean_y};
}

void require_aspect(double aspect) {
  if (!(aspect > 0.0) || !std::isfinite(aspect)) {
    throw std::invalid_argument("footprint: the aspect must be finite and positive");
  }
}

}  // namespace

std::optional<Footprint> free_footprint(std::span<const LoadedCell> cells, CellSize size,
                                        std::span<const CellCentre> unloaded) {
  require_cell_size(size);
  return free_fit(cells, size, unloaded);
}

std::optional<double> footprint_area_at_aspect_mm2(std::span<const LoadedCell> cells, CellSize size,
                                                   double aspect,
                                                   std::span<const CellCentre> unloaded) {
  require_cell_size(size);
  require_aspect(aspect);
  const auto fit = cap_at_aspect(cells, size, aspect);
  if (!fit) return std::nullopt;
  return cap_area_mm2(fit->cap, cells.size(), unloaded, fit->mean_x, fit->mean_y, size);
}

std::optional<double> footprint_area_unthresholded_mm2(std::span<const LoadedCell> region_cells,
                                                       CellSize size, double aspect,
                                                       double threshold_bits) {
  require_cell_size(size);
  require_aspect(aspect);
  // The set grows or shrinks by a rim of cells a round and settles in two or three. Where it
  // does not, a cell at the rim is going in and out as the cap's edge crosses its centre: it
  // reads next to nothing either way, and the last round's fit stands.
  constexpr int kMaxRounds = 8;
  std::vector<bool> covered(region_cells.size());
  for (std::size_t i = 0; i < region_cells.size(); ++i) {
    covered[i] = region_cells[i].load >= threshold_bits;
  }
  std::vector<LoadedCell> cells;
  std::optional<double> area;
  for (int round = 0; round < kMaxRounds; ++round) {
    cells.clear();
    for (std::size_t i = 0; i < region_cells.size(); ++i) {
      if (covered[i]) cells.push_back(region_cells[i]);
    }
    const auto fit = cap_at_aspect(cells, size, aspect);
    if (!fit) return std::nullopt;
    area = cap_area_mm2(fit->cap, cells.size(), {}, fit->mean_x, fit->mean_y, size);
    if (!area) return std::nullopt;
    const Quadratic& q = fit->cap;
    bool settled = true;
    for (std::size_t i = 0; i < region_cells.size(); ++i) {
      const double u = (region_cells[i].x_mm - fit->mean_x) / size.width_mm;
      const double v = (region_cells[i].y_mm - fit->mean_y) / size.height_mm;
      const bool inside = q.q0 + q.q1 * u + q.q2 * v + q.q3 * u * u + q.q4 * v * v > 0.0;
      settled = settled && inside == covered[i];
      covered[i] = inside;
    }
    if (settled) break;
  }
  return area;
}

std::optional<double> shared_aspect(std::span<const Footprint> footprints) {
  // Each frame's aspect is as uncertain as its loads are small against the noise, so frames
  // weigh by their peak squared; log keeps A/B and B/A symmetric.
  double sum = 0.0;
  double weight = 0.0;
  for (const Footprint& f : footprints) {
    if (!(f.aspect > 0.0) || !std::isfinite(f.aspect) || !(f.peak > 0.0) ||
        !std::isfinite(f.peak)) {
      continue;
    }
    sum += f.peak * f.peak * std::log(f.aspect);
    weight += f.peak * f.peak;
  }
  if (!(weight > 0.0)) return std::nullopt;
  return std::exp(sum / weight);
}

}  // namespace gaitmon
