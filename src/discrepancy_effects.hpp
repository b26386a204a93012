// The discrepancy workflow's units (one region of one step) and its library of candidate effects;
// shared by src/discrepancy.cpp, which fits them, and src/discrepancy_effects.cpp, which defines
// them. Internal: not part of the public API.
#pragma once

#include <array>
#include <cstddef>
#include <functional>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "gaitmon/tissue_model.hpp"
#include "gaitmon/types.hpp"

namespace gaitmon::discrepancy_detail {

// The baseline's shapes of one region's series, F = K En[k] + D V: the elastic shape for the
// step fit's n (first) and for a grid of n, the damping shape, and the deformation and its rate.
struct Shapes {
  std::vector<std::vector<double>> En;
  std::vector<double> V, d_mm, ddot_mm_per_s;
};

// What the shapes of a unit are computed from besides its series: its step fit's parameters.
struct ShapeModel {
  IdentifiableParams id{};
  double C_mm = 0.0;
  ModelVariant model = ModelVariant::Correct;
};

Shapes shapes_of(std::span<const double> t_s, std::span<const double> area_mm2,
                 const ShapeModel& m);

inline constexpr std::string_view kCrosstalk = "crosstalk";

// Couplings at which each step was measured again with its readings corrected for crosstalk
// (DiscrepancyStep::crosstalk); between them the areas and forces are interpolated.
inline constexpr std::array<double, 8> kCrosstalkGrid{0.01,  0.02, 0.035, 0.05,
                                                      0.075, 0.1,  0.15,  0.2};

// A unit measured again with its readings corrected for crosstalk: per coupling of
// kCrosstalkGrid and frame, its area, what the correction took off its force and what its cells
// read of other regions' cells (N; CrosstalkView::spill_in_n).
struct CrosstalkSeries {
  std::vector<std::vector<double>> area_mm2, removed_n, spill_in_n;
};

// One region of one step: the measured series and the baseline's shapes.
struct Unit {
  int ordinal = 0;           // the step's place in time order (both feet)
  double t_contact_s = 0.0;  // the region's first frame with a contact, fitted or not
  Foot foot = Foot::Left;
  int step = 0;
  Region region = Region::Heel;
  std::vector<double> t, y, area, E, V, d_mm, ddot_mm_per_s, phase, floor2, sat;
  std::vector<std::size_t> series_frames;  // per frame, its index in the step's region series
  // Elastic shapes for the fit's n (first) and a grid of n: the exponent is re-chosen with every
  // effect, since a per-step fit bends n to absorb what the model lacks.
  std::vector<std::vector<double>> En;
  ShapeModel shape_model;
  // Null where the steps were not measured again; shared, since the crosstalk candidate copies
  // each unit as the other effects then see it (Applied::seen).
  std::shared_ptr<const CrosstalkSeries> crosstalk;
  double K0 = 0.0, D0 = 0.0;
  double base_sse = 0.0;
  std::vector<double> base_pred;
  double peak_n = 0.0;
  double dt_s = 0.01;
  int prev = -1;  // the foot's previous unit of the same region, in time order
  // The zero channel. What the per-step zeroing took off this region (its cells' mean reading
  // in the swing windows around the step, N) and when those windows were read. Units of the
  // foot's consecutive steps form a chain, and the change of the zero from the unit before in
  // the chain is observed. A chain that does not start at the foot's first contact carries a
  // lag from loads nobody analysed (a recording that starts in stance): unknown, and solved for.
  double zero_n = 0.0;
  int cells = 0;  // the region's cells, whose zeros zero_n sums
  double t_pre_zero_s = std::numeric_limits<double>::quiet_NaN();
  double t_post_zero_s = std::numeric_limits<double>::quiet_NaN();
  int chain = -1;  // the unit that starts its chain
  bool zero_change = false;
  bool unknown_start = false;  // on a chain's first unit
  double norm() const { return static_cast<double>(y.size()) * peak_n * peak_n; }
};

// An effect with its shared parameters fixed, ready to transform model forces unit by unit.
class Applied {
 public:
  virtual ~Applied() = default;
  virtual bool affects(const Unit& u) const = 0;
  /// Measured force predicted from the model force F of unit `ui`, with the unit's own choice
  /// among the effect's per-step alternatives (0 <= choice < choices(u)).
  virtual void apply(std::size_t ui, const Unit& u, std::span<const double> F,
                     std::span<double> out, std::size_t choice) const = 0;
  /// Alternatives that belong to each step, not to the session: each unit takes the one that
  /// fits it best, as it takes its n (impact's onset between two frames). 1 for none.
  virtual std::size_t choices(const Unit& /*u*/) const { return 1; }
  virtual bool affine() const { return true; }
  /// An effect that maps each frame's force on its own, out_i = s(F_i), also writes ds/dF per
  /// frame and returns true, so Gauss-Newton through it needs no differences; any other returns
  /// false and writes nothing.
  virtual bool apply_with_slope(std::size_t /*ui*/, const Unit& /*u*/,
                                std::span<const double> /*F*/, std::span<double> /*out*/,
                                std::span<double> /*slope*/) const {
    return false;
  }
  /// out = F + something that does not depend on F: the chain's linear part is the same with
  /// and without it, whatever the choice.
  virtual bool additive() const { return false; }
  /// What the effect adds to unit `ui`'s reading in the swing windows its zero was taken from
  /// (N): the share of it that the per-step zeroing took off. Only a sensor effect that reads
  /// without a load has one.
  virtual double swing_reading(std::size_t /*ui*/) const { return 0.0; }
  /// What it adds there per unit of lag at the start of the unit's chain, where that is unknown.
  virtual double swing_reading_per_start_lag(std::size_t /*ui*/) const { return 0.0; }
  /// An effect of the measurement on the area the model is driven by gives the unit as the
  /// model and the other effects in the chain then see it: the area it corrects, and the shapes,
  /// deformation and rate from that area; nullptr keeps the unit as measured.
  virtual const Unit* seen(std::size_t /*ui*/) const { return nullptr; }
};

struct ParamSpec {
  std::string name;
  double lo, hi;
  std::vector<double> grid;
};

struct CandidateSpec {
  std::string name;
  // The order in which effects chain, as the simulator applies them: 0 tissue, 1 sensor (each
  // cell), 2 frame (the cells together, after the sensor stage: crosstalk).
  int stage = 0;
  std::vector<ParamSpec> params;
  std::function<std::unique_ptr<Applied>(const std::vector<Unit>&, std::span<const double>)> make;
  bool reads_in_swing = false;  // solves each chain's unknown start lag (Pooled::unknown_starts)
  bool needs_ceiling = false;   // named only where the readings show a ceiling (ceiling_seen)
};

/// Replaces each NaN of `v` by the nearest value that is not (the later one where two are as
/// near), or by `otherwise` where there is none: a frame without a measurement of its own takes
/// its neighbour's.
void fill_from_nearest(std::vector<double>& v, double otherwise);

/// The candidates in the order the workflow tries them, with their parameter ranges and grids.
std::vector<CandidateSpec> candidate_specs(double cell_area_mm2, double newtons_per_bit);

}  // namespace gaitmon::discrepancy_detail
