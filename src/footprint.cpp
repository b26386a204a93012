// The paraboloid footprint fitted to a region's cell loads (see footprint.hpp for the derivation).
#include "gaitmon/footprint.hpp"

#include <ceres/tiny_solver.h>

#include <Eigen/Core>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
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

// Columns of the midpoint rule across a cell the rim crosses; along each column the mean is
// exact. 8 puts the rule's error in the cell's mean well under the noise of half a bit
// (tests/footprint_test.cpp).
constexpr int kColumns = 8;
// Each column's centre from the cell's, in cell widths: the midpoint rule's.
constexpr std::array<double, kColumns> kColumnOffsets = [] {
  std::array<double, kColumns> offsets{};
  for (int a = 0; a < kColumns; ++a) offsets[a] = (a + 0.5) / kColumns - 0.5;
  return offsets;
}();

/// The clipped paraboloid p = pmax max(0, 1 - u^2 - v^2), u = (x - x0) / rA, v = (y - y0) / rB,
/// rB = rA / aspect, as each region cell reads it (at its centre or averaged over its area),
/// against the cells' readings: the residuals and their Jacobian in pmax, x0, y0, rA for
/// ceres::TinySolver.
class CellCap {
  using Columns = Eigen::Array<double, kColumns, 1>;

 public:
  using Scalar = double;
  enum { NUM_RESIDUALS = Eigen::Dynamic, NUM_PARAMETERS = 4 };

  CellCap(std::span<const LoadedCell> cells, CellSize size, double aspect, CellReading reading)
      : cells_(cells),
        size_(size),
        aspect_(aspect),
        reading_(reading),
        kept_x_(Eigen::Vector4d::Constant(std::numeric_limits<double>::quiet_NaN())),
        kept_residuals_(cells.size()),
        kept_jacobian_(4 * cells.size()) {}

  int NumResiduals() const { return static_cast<int>(cells_.size()); }

  // TinySolver works out each trial step's residuals alone and, where it takes the step, the
  // same point again with the Jacobian. Working out the Jacobian with the residuals the first
  // time and keeping it halves the evaluations of the cells' readings, most of the fit's time.
  bool operator()(const double* parameters, double* residuals, double* jacobian) const {
    const Eigen::Map<const Eigen::Vector4d> x(parameters);
    const std::size_t n = cells_.size();
    if (jacobian == nullptr || x != kept_x_) {
      kept_x_.setConstant(std::numeric_limits<double>::quiet_NaN());
      if (!evaluate(parameters, kept_residuals_.data(), kept_jacobian_.data())) return false;
      kept_x_ = x;
    }
    std::copy_n(kept_residuals_.data(), n, residuals);
    if (jacobian != nullptr) std::copy_n(kept_jacobian_.data(), 4 * n, jacobian);
    return true;
  }

 private:
  /// The cap's centre, its inverse semi-axes, and a cell's half sides in (u, v).
  struct Cap {
    double x0, y0, inv_rA, inv_rB, half_u, half_v;
  };

  /// The cell's reading of max(0, 1 - u^2 - v^2) and its derivatives in x0, y0, rA.
  struct Reading {
    double value = 0.0, d_x0 = 0.0, d_y0 = 0.0, d_rA = 0.0;
  };

  bool evaluate(const double* parameters, double* residuals, double* jacobian) const {
    const double pmax = parameters[0];
    const double rA = parameters[3];
    if (!(std::abs(rA) > 0.0) || !std::isfinite(rA)) return false;
    // The divisions are the evaluation's, not each cell's.
    const double rB = rA / aspect_;
    const Cap cap{parameters[1],
                  parameters[2],
                  1.0 / rA,
                  1.0 / rB,
                  0.5 * size_.width_mm / std::abs(rA),
                  0.5 * size_.height_mm / std::abs(rB)};
    const std::size_t n = cells_.size();
    for (std::size_t i = 0; i < n; ++i) {
      const Reading m =
          reading_ == CellReading::Mean ? cell_mean(cells_[i], cap) : at_centre(cells_[i], cap);
      residuals[i] = pmax * m.value - cells_[i].load;
      jacobian[i] = m.value;
      jacobian[n + i] = pmax * m.d_x0;
      jacobian[2 * n + i] = pmax * m.d_y0;
      jacobian[3 * n + i] = pmax * m.d_rA;
    }
    return true;
  }

  static Reading at_centre(const LoadedCell& c, const Cap& cap) {
    const double uc = (c.x_mm - cap.x0) * cap.inv_rA;
    const double vc = (c.y_mm - cap.y0) * cap.inv_rB;
    const double s = uc * uc + vc * vc;
    if (s >= 1.0) return {};
    return {1.0 - s, 2.0 * uc * cap.inv_rA, 2.0 * vc * cap.inv_rB, 2.0 * s * cap.inv_rA};
  }

  static Reading cell_mean(const LoadedCell& c, const Cap& cap) {
    const double half_u = cap.half_u;
    const double half_v = cap.half_v;
    const double uc = (c.x_mm - cap.x0) * cap.inv_rA;
    const double vc = (c.y_mm - cap.y0) * cap.inv_rB;
    // In (u, v) the cell is a rectangle and the contact the unit disc.
    const double near_u = std::max(0.0, std::abs(uc) - half_u);
    const double near_v = std::max(0.0, std::abs(vc) - half_v);
    if (near_u * near_u + near_v * near_v >= 1.0) return {};
    const double far_u = std::abs(uc) + half_u;
    const double far_v = std::abs(vc) + half_v;
    if (far_u * far_u + far_v * far_v <= 1.0) {
      // Wholly covered: a quadratic's mean over a rectangle is its value at the centre plus its
      // second derivatives times the side squared over 24, which the rule could only approach.
      const double s = uc * uc + vc * vc + (half_u * half_u + half_v * half_v) / 3.0;
      return {1.0 - s, 2.0 * uc * cap.inv_rA, 2.0 * vc * cap.inv_rB, 2.0 * s * cap.inv_rA};
    }
    // Along a column at u the cap is 1 - u^2 - v^2 between v = +-sqrt(1 - u^2), and its integral
    // over the cell's span [lo, hi] and those of its derivatives are closed forms; the rim adds
    // nothing to the derivatives, as the cap is zero there. The columns are worked out together
    // without branches (a column the cap misses has lo = hi), which lets them share vector
    // instructions: this is most of the cell-mean fit's time.
    const Columns u = uc + 2.0 * half_u * Eigen::Map<const Columns>(kColumnOffsets.data());
    const Columns reach2 = (1.0 - u.square()).max(0.0);
    const Columns reach = reach2.sqrt();
    const Columns lo = (-reach).max(vc - half_v);
    const Columns hi = reach.min(vc + half_v).max(lo);
    const Columns span = hi - lo;
    const Columns cubes = (hi.cube() - lo.cube()) * (1.0 / 3.0);
    // Each column's integral is in v; the cell's mean divides by its height in v, 2 half_v.
    const double per_column = 1.0 / (kColumns * 2.0 * half_v);
    return {(reach2 * span - cubes).sum() * per_column,
            2.0 * cap.inv_rA * (u * span).sum() * per_column,
            (hi.square() - lo.square()).sum() * cap.inv_rB * per_column,
            2.0 * cap.inv_rA * (u.square() * span + cubes).sum() * per_column};
  }

  std::span<const LoadedCell> cells_;
  CellSize size_;
  double aspect_;
  CellReading reading_;
  mutable Eigen::Vector4d kept_x_;
  mutable std::vector<double> kept_residuals_;
  mutable std::vector<double> kept_jacobian_;
};

/// pmax, x0, y0, rA to start the cell-mean fit from: the four-term fit's cap over the cells at
/// or above the threshold, or where that is no cap, their load-weighted centroid and an ellipse
/// of their area.
Eigen::Vector4d cell_mean_start(std::span<const LoadedCell> active, CellSize size, double aspect) {
  if (const auto fit = cap_at_aspect(active, size, aspect)) {
    const Quadratic& q = fit->cap;
    const double peak = q.q3 < 0.0 && q.q4 < 0.0
                            ? q.q0 - q.q1 * q.q1 / (4.0 * q.q3) - q.q2 * q.q2 / (4.0 * q.q4)
                            : 0.0;
    if (peak > 0.0) {
      return {peak, fit->mean_x - q.q1 / (2.0 * q.q3) * size.width_mm,
              fit->mean_y - q.q2 / (2.0 * q.q4) * size.height_mm,
              std::sqrt(-peak / q.q3) * size.width_mm};
    }
  }
  double sum = 0.0, x = 0.0, y = 0.0, peak = 0.0;
  for (const LoadedCell& c : active) {
    sum += c.load;
    x += c.load * c.x_mm;
    y += c.load * c.y_mm;
    peak = std::max(peak, c.load);
  }
  const double area = static_cast<double>(active.size()) * size.width_mm * size.height_mm;
  return {peak, x / sum, y / sum, std::sqrt(area * aspect / std::numbers::pi)};
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

std::optional<CellCapFit> fit_cell_cap(std::span<const LoadedCell> region_cells, CellSize size,
                                       double aspect, double threshold_bits, CellReading reading) {
  require_cell_size(size);
  require_aspect(aspect);
  if (!centroid(region_cells)) return std::nullopt;
  std::vector<LoadedCell> active;
  for (const LoadedCell& c : region_cells) {
    if (c.load >= threshold_bits && c.load > 0.0) active.push_back(c);
  }
  if (active.size() < 4) return std::nullopt;
  Eigen::Vector4d x = cell_mean_start(active, size, aspect);
  const CellCap cap(region_cells, size, aspect, reading);
  ceres::TinySolver<CellCap> solver;
  solver.options.max_num_iterations = 100;
  // Millimetre-scale geometry: these stop well below a micrometre of change in the centre and rA.
  solver.options.gradient_tolerance = 1e-10;
  solver.options.parameter_tolerance = 1e-9;
  solver.options.function_tolerance = 1e-10;
  const auto& summary = solver.Solve(cap, &x);
  if (summary.status == ceres::TinySolver<CellCap>::HIT_MAX_ITERATIONS) return std::nullopt;
  if (!x.allFinite() || !(x[0] > 0.0)) return std::nullopt;
  const double area = std::numbers::pi * x[3] * x[3] / aspect;
  const double sensor_area = static_cast<double>(active.size()) * size.width_mm * size.height_mm;
  if (!(area >= kMinAreaOfSensorArea * sensor_area && area <= kMaxAreaOfSensorArea * sensor_area)) {
    return std::nullopt;
  }
  // TinySolver's cost is half the sum of squares.
  return CellCapFit{area, 2.0 * summary.final_cost, static_cast<int>(region_cells.size())};
}

std::optional<double> footprint_area_cell_mean_mm2(std::span<const LoadedCell> region_cells,
                                                   CellSize size, double aspect,
                                                   double threshold_bits) {
  const auto fit = fit_cell_cap(region_cells, size, aspect, threshold_bits, CellReading::Mean);
  if (!fit) return std::nullopt;
  return fit->area_mm2;
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
