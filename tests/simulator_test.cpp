// Tests of the session simulator: rasterisation, determinism, the written session and its truth.
#include "gaitmon/simulator.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "gaitmon/config.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/session.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

using test::kPi;

using test::shipped_config;

const InsoleLayout& layout_37_38() {
  static const InsoleLayout layout(shipped_config().insole(InsoleSize::S37_38),
                                   shipped_config().sensor);
  return layout;
}

EllipsoidParams seed_means(Region region) {
  return shipped_config().tissue(InsoleSize::S37_38, region).mean;
}

// The model written out again here, so that the expected values do not come from the code under
// test: eq 32, eqs 5-6, eqs 14-15 and the integral of eq 22 (model-notes section 1).
double deformation(const EllipsoidParams& p, double area) {
  return p.C_mm * (1.0 - std::sqrt(1.0 - area / (kPi * p.A_mm * p.B_mm)));
}

double radius_a(const EllipsoidParams& p, double d) {
  return p.A_mm * std::sqrt(2 * p.C_mm * d - d * d) / p.C_mm;
}

double radius_b(const EllipsoidParams& p, double d) {
  return p.B_mm * std::sqrt(2 * p.C_mm * d - d * d) / p.C_mm;
}

double closed_form_force(const EllipsoidParams& p, double d, double ddot) {
  const double C = p.C_mm;
  const double k = p.kbar_n_per_mm3 * std::pow(d / p.d0_mm, p.n);
  const double c = p.cbar_ns_per_mm3 * std::pow(d / p.d0_mm, p.m);
  return kPi * p.A_mm * p.B_mm * d / C *
         (k * (d - d * d / (3 * C)) +
          c * ddot * (6 * C * C - 4 * C * d + d * d) / (3 * C * (2 * C - d)));
}

double pressure(const EllipsoidParams& p, double d, double ddot, double rho2) {
  if (rho2 > 1.0) return 0.0;
  const double C = p.C_mm;
  const double k = p.kbar_n_per_mm3 * std::pow(d / p.d0_mm, p.n);
  const double c = p.cbar_ns_per_mm3 * std::pow(d / p.d0_mm, p.m);
  const double root = std::sqrt(C * C - rho2 * (2 * C * d - d * d));
  return k * (d - C + root) + c * ddot * (1.0 - rho2 * (C - d) / root);
}

struct Cells {
  std::vector<double> x;
  std::vector<double> y;
  double cx = 0.0;
  double cy = 0.0;
  double box_aspect = 1.0;  ///< width / height of the cells' bounding box, cell edges included
};

Cells region_cells(Region region) {
  Cells cells;
  for (std::size_t index : layout_37_38().region_sensors(region)) {
    cells.x.push_back(layout_37_38().sensor(index).grid_x_mm);
    cells.y.push_back(layout_37_38().sensor(index).grid_y_mm);
  }
  // The footprint is centred on the cells' bounding box and stretched, area kept, to its aspect.
  const auto [x_lo, x_hi] = std::minmax_element(cells.x.begin(), cells.x.end());
  const auto [y_lo, y_hi] = std::minmax_element(cells.y.begin(), cells.y.end());
  cells.cx = 0.5 * (*x_lo + *x_hi);
  cells.cy = 0.5 * (*y_lo + *y_hi);
  cells.box_aspect = (*x_hi - *x_lo + 7.5) / (*y_hi - *y_lo + 15.0);
  return cells;
}

// The footprint's semi-axes: eqs 5-6 with x stretched and y shrunk by sqrt(box aspect / (A/B)).
double footprint_ra(const Cells& cells, const EllipsoidParams& p, double d) {
  return radius_a(p, d) * std::sqrt(cells.box_aspect / (p.A_mm / p.B_mm));
}

double footprint_rb(const Cells& cells, const EllipsoidParams& p, double d) {
  return radius_b(p, d) / std::sqrt(cells.box_aspect / (p.A_mm / p.B_mm));
}

struct RasterCase {
  Region region;
  double area_fraction_of_sensors;
  double ddot_mm_per_s;
};

const std::vector<RasterCase> kRasterCases{
    {Region::Heel, 0.3, 40.0},
    {Region::Heel, 0.85, -20.0},
    {Region::Met3_5, 0.5, 10.0},
    {Region::Met1_2, 0.9, -60.0},
    {Region::Toe2, 0.6, 30.0},
    {Region::Toes3_5, 0.2, 0.0},
    {Region::MidfootAnterior, 0.7, 25.0},
};

double sensor_area(Region region) {
  return static_cast<double>(layout_37_38().region_sensors(region).size()) * 7.5 * 15.0;
}

// The rescaling to the force given, and loads never negative; how the loads are spread is
// checked against the pressure field in the tests below.
TEST(Simulator, RasterisedCellsAreRescaledToTheForceGivenInBothModes) {
  for (const RasterCase& rc : kRasterCases) {
    const EllipsoidParams p = seed_means(rc.region);
    const double d = deformation(p, rc.area_fraction_of_sensors * sensor_area(rc.region));
    const double force = closed_form_force(p, d, rc.ddot_mm_per_s);
    ASSERT_GT(force, 0.0);
    for (Rasterisation mode : {Rasterisation::CellCentre, Rasterisation::Coverage}) {
      const std::vector<double> loads = rasterise_region(
          layout_37_38(), rc.region, p, d, rc.ddot_mm_per_s, ModelVariant::Correct, mode, force);
      ASSERT_EQ(loads.size(), layout_37_38().region_sensors(rc.region).size());
      double sum = 0.0;
      for (double load : loads) {
        EXPECT_GE(load, 0.0);
        sum += load;
      }
      EXPECT_NEAR(sum, force, 1e-12 * force) << region_name(rc.region);
    }
  }
}

TEST(Simulator, CellCentreLoadsFollowThePressureAtCellCentres) {
  for (const RasterCase& rc : kRasterCases) {
    const EllipsoidParams p = seed_means(rc.region);
    const double d = deformation(p, rc.area_fraction_of_sensors * sensor_area(rc.region));
    const double ddot = rc.ddot_mm_per_s;
    const double force = closed_form_force(p, d, ddot);
    const Cells cells = region_cells(rc.region);
    const double ra = footprint_ra(cells, p, d);
    const double rb = footprint_rb(cells, p, d);
    std::vector<double> expected(cells.x.size(), 0.0);
    double total = 0.0;
    for (std::size_t i = 0; i < cells.x.size(); ++i) {
      const double u = (cells.x[i] - cells.cx) / ra;
      const double v = (cells.y[i] - cells.cy) / rb;
      expected[i] = std::max(0.0, pressure(p, d, ddot, u * u + v * v));
      total += expected[i];
    }
    if (total == 0.0) {
      // No centre inside (toe2's two cells sit in two rows, and its ellipse is wide
      // and low): the cell nearest the ellipse's centre, the first on a tie, takes everything.
      std::size_t nearest = 0;
      for (std::size_t i = 1; i < cells.x.size(); ++i) {
        if (std::hypot(cells.x[i] - cells.cx, cells.y[i] - cells.cy) <
            std::hypot(cells.x[nearest] - cells.cx, cells.y[nearest] - cells.cy)) {
          nearest = i;
        }
      }
      expected[nearest] = 1.0;
      total = 1.0;
    }
    const std::vector<double> loads =
        rasterise_region(layout_37_38(), rc.region, p, d, ddot, ModelVariant::Correct,
                         Rasterisation::CellCentre, force);
    for (std::size_t i = 0; i < loads.size(); ++i) {
      EXPECT_NEAR(loads[i], force * expected[i] / total, 1e-9 * force) << region_name(rc.region);
    }
  }
}

// A placement shift moves the whole contact ellipse on the grid: each cell then reads the
// pressure at its centre measured from the shifted centre, and the loads still sum to the force.
TEST(Simulator, PlacementShiftMovesTheFootprintOnTheCellGrid) {
  const PlacementShift shift{2.5, -4.0};
  for (Region region : {Region::Heel, Region::Met1_2}) {
    const EllipsoidParams p = seed_means(region);
    const double d = deformation(p, 0.5 * sensor_area(region));
    const double force = closed_form_force(p, d, 0.0);
    const Cells cells = region_cells(region);
    const double ra = footprint_ra(cells, p, d);
    const double rb = footprint_rb(cells, p, d);
    std::vector<double> expected(cells.x.size(), 0.0);
    double total = 0.0;
    for (std::size_t i = 0; i < cells.x.size(); ++i) {
      const double u = (cells.x[i] - cells.cx - shift.x_mm) / ra;
      const double v = (cells.y[i] - cells.cy - shift.y_mm) / rb;
      expected[i] = std::max(0.0, pressure(p, d, 0.0, u * u + v * v));
      total += expected[i];
    }
    ASSERT_GT(total, 0.0);
    const auto loads = rasterise_region(layout_37_38(), region, p, d, 0.0, ModelVariant::Correct,
                                        Rasterisation::CellCentre, force, shift);
    const auto centred = rasterise_region(layout_37_38(), region, p, d, 0.0, ModelVariant::Correct,
                                          Rasterisation::CellCentre, force);
    double moved = 0.0;
    for (std::size_t i = 0; i < loads.size(); ++i) {
      EXPECT_NEAR(loads[i], force * expected[i] / total, 1e-9 * force) << region_name(region);
      moved += std::abs(loads[i] - centred[i]);
    }
    EXPECT_GT(moved, 0.05 * force) << region_name(region);
  }
}

TEST(Simulator, CellCentreGivesATinyContactToTheNearestCell) {
  const EllipsoidParams p = seed_means(Region::Heel);
  const double d = deformation(p, 10.0);  // a 10 mm^2 ellipse: no cell centre inside
  const Cells cells = region_cells(Region::Heel);
  std::size_t nearest = 0;
  double best = 1e300;
  for (std::size_t i = 0; i < cells.x.size(); ++i) {
    const double dist = std::hypot(cells.x[i] - cells.cx, cells.y[i] - cells.cy);
    if (dist > 1e-9 && dist < std::max(footprint_ra(cells, p, d), footprint_rb(cells, p, d)))
      FAIL() << "a centre is inside the tiny ellipse";
    if (dist < best) {
      best = dist;
      nearest = i;
    }
  }
  const std::vector<double> loads =
      rasterise_region(layout_37_38(), Region::Heel, p, d, 5.0, ModelVariant::Correct,
                       Rasterisation::CellCentre, 3.0);
  for (std::size_t i = 0; i < loads.size(); ++i) EXPECT_EQ(loads[i], i == nearest ? 3.0 : 0.0);
}

TEST(Simulator, CoverageLoadsFullCellsWithTheirMeanPressureAndEmptyCellsWithNothing) {
  // A heel contact of 1000 mm^2 lies within the heel's cells, so the rescaling is close to 1
  // and a fully covered cell carries its mean pressure times its area.
  const Region region = Region::Heel;
  const EllipsoidParams p = seed_means(region);
  const double d = deformation(p, 1000.0);
  const double ddot = 30.0;
  const double force = closed_form_force(p, d, ddot);
  const Cells cells = region_cells(region);
  const double ra = footprint_ra(cells, p, d);
  const double rb = footprint_rb(cells, p, d);
  const double w = 7.5;
  const double h = 15.0;
  const std::vector<double> loads = rasterise_region(
      layout_37_38(), region, p, d, ddot, ModelVariant::Correct, Rasterisation::Coverage, force);
  int full = 0;
  int empty = 0;
  int partial = 0;
  for (std::size_t i = 0; i < cells.x.size(); ++i) {
    // Corners inside the ellipse -> the convex ellipse covers the whole cell.
    int corners_inside = 0;
    for (double sx : {-0.5, 0.5}) {
      for (double sy : {-0.5, 0.5}) {
        const double u = (cells.x[i] + sx * w - cells.cx) / ra;
        const double v = (cells.y[i] + sy * h - cells.cy) / rb;
        corners_inside += u * u + v * v < 1.0 ? 1 : 0;
      }
    }
    const double gap_x = std::max(0.0, std::abs(cells.x[i] - cells.cx) - 0.5 * w);
    const double gap_y = std::max(0.0, std::abs(cells.y[i] - cells.cy) - 0.5 * h);
    const bool disjoint = (gap_x / ra) * (gap_x / ra) + (gap_y / rb) * (gap_y / rb) >= 1.0;
    if (corners_inside == 4) {
      ++full;
      // The mean pressure over the cell by a 200 x 200 midpoint rule.
      double sum = 0.0;
      for (int a = 0; a < 200; ++a) {
        for (int b = 0; b < 200; ++b) {
          const double u = (cells.x[i] + w * ((a + 0.5) / 200 - 0.5) - cells.cx) / ra;
          const double v = (cells.y[i] + h * ((b + 0.5) / 200 - 0.5) - cells.cy) / rb;
          sum += pressure(p, d, ddot, u * u + v * v);
        }
      }
      const double expected = sum / (200.0 * 200.0) * w * h;
      EXPECT_NEAR(loads[i], expected, 0.02 * expected) << "cell " << i;
    } else if (disjoint) {
      ++empty;
      EXPECT_EQ(loads[i], 0.0) << "cell " << i;
    } else {
      ++partial;
    }
  }
  EXPECT_GE(full, 2);
  EXPECT_GE(empty, 5);
  EXPECT_GE(partial, 4);
}

TEST(Simulator, CoverageActivatesMoreCellsThanCellCentre) {
  int more = 0;
  for (const RasterCase& rc : kRasterCases) {
    const EllipsoidParams p = seed_means(rc.region);
    const double d = deformation(p, rc.area_fraction_of_sensors * sensor_area(rc.region));
    const double force = closed_form_force(p, d, rc.ddot_mm_per_s);
    const auto count = [&](Rasterisation mode) {
      const auto loads = rasterise_region(layout_37_38(), rc.region, p, d, rc.ddot_mm_per_s,
                                          ModelVariant::Correct, mode, force);
      return std::count_if(loads.begin(), loads.end(), [](double v) { return v > 0.0; });
    };
    const auto centre = count(Rasterisation::CellCentre);
    const auto coverage = count(Rasterisation::Coverage);
    EXPECT_GE(coverage, centre) << region_name(rc.region);
    more += coverage > centre ? 1 : 0;
  }
  EXPECT_GE(more, 3);
}

TEST(Simulator, PeakAreaBisectionHitsTheTargetElasticForce) {
  const EllipsoidParams p = seed_means(Region::Met3_5);
  const double area = contact_area_for_elastic_force(p, 250.0, 3000.0);
  EXPECT_NEAR(closed_form_force(p, deformation(p, area), 0.0), 250.0, 1e-6);
  // Unreachable within the cap: the cap itself.
  EXPECT_EQ(contact_area_for_elastic_force(p, 1e6, 3000.0), 3000.0);
  EXPECT_EQ(contact_area_for_elastic_force(p, 0.0, 3000.0), 0.0);
}

// The planned area course other code rebuilds the truth from: nothing outside the region's
// window (the heel's 0-0.52 of the contact, written in the truth JSON), its peak area at the
// window's peak, and a rate that is the course's derivative (central differences).
TEST(Simulator, PlannedContactAreaIsTheBumpAndItsRate) {
  SimulatedRegion heel;
  heel.peak_area_mm2 = 3000.0;
  EXPECT_EQ(planned_contact_area_mm2(heel, Region::Heel, 0.0).first, 0.0);
  EXPECT_EQ(planned_contact_area_mm2(heel, Region::Heel, 0.6).first, 0.0);
  EXPECT_EQ(planned_contact_area_mm2(heel, Region::Heel, 0.6).second, 0.0);
  EXPECT_NEAR(planned_contact_area_mm2(heel, Region::Heel, 0.12).first, 3000.0, 1e-9);
  EXPECT_NEAR(planned_contact_area_mm2(heel, Region::Heel, 0.06).first, 1500.0, 1e-9);
  constexpr double h = 1e-6;
  for (double u : {0.03, 0.1, 0.2, 0.4, 0.5}) {
    const double numeric = (planned_contact_area_mm2(heel, Region::Heel, u + h).first -
                            planned_contact_area_mm2(heel, Region::Heel, u - h).first) /
                           (2 * h);
    EXPECT_NEAR(planned_contact_area_mm2(heel, Region::Heel, u).second, numeric,
                1e-5 * std::abs(numeric) + 1e-3)
        << u;
  }
}

TEST(Simulator, EffectRegistryListsNoneAndTheSevenPhysicalEffects) {
  EXPECT_EQ(simulation_effect_names(),
            (std::vector<std::string_view>{"none", "stress_relaxation", "hysteresis",
                                           "impact_transient", "sensor_saturation", "sensor_creep",
                                           "thermal_drift", "crosstalk"}));
  EXPECT_EQ(make_simulation_effect("none"), nullptr);
  EXPECT_NE(make_simulation_effect("hysteresis"), nullptr);
  EXPECT_THROW(make_simulation_effect("ghosting"), std::invalid_argument);
}

std::string slurp(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

SimulationOptions short_options(std::uint64_t seed) {
  SimulationOptions o;
  o.duration_s = 12.0;
  o.seed = seed;
  return o;
}

TEST(Simulator, SameSeedSameBytesOtherSeedOtherBytes) {
  const auto dir = test::scratch_dir("sim-determinism");
  for (Rasterisation mode : {Rasterisation::CellCentre, Rasterisation::Coverage}) {
    SimulationOptions o = short_options(7);
    o.rasterisation = mode;
    simulate_session(shipped_config(), o, dir / "a.csv", dir / "a.json");
    simulate_session(shipped_config(), o, dir / "b.csv", dir / "b.json");
    o.effects = {"none"};
    simulate_session(shipped_config(), o, dir / "n.csv", dir / "n.json");
    o.seed = 8;
    simulate_session(shipped_config(), o, dir / "c.csv", dir / "c.json");
    const std::string a = slurp(dir / "a.csv");
    ASSERT_GT(a.size(), 100000u);
    EXPECT_EQ(a, slurp(dir / "b.csv"));
    EXPECT_EQ(slurp(dir / "a.json"), slurp(dir / "b.json"));
    EXPECT_EQ(a, slurp(dir / "n.csv"));
    EXPECT_NE(a, slurp(dir / "c.csv"));
  }
}

SimulationOptions minute_options() {
  SimulationOptions o = short_options(5);
  o.duration_s = 60.0;
  return o;
}

// Simulates `o` as it is and again after `ask_for_zero` sets a variation to 0, which must keep
// every byte: the variation's draws are made only when it is asked for.
SimulationTruth simulate_kept_by_zero(const std::filesystem::path& dir, SimulationOptions o,
                                      void (*ask_for_zero)(SimulationOptions&)) {
  const SimulationTruth fixed =
      simulate_session(shipped_config(), o, dir / "fixed.csv", dir / "fixed.json");
  ask_for_zero(o);
  simulate_session(shipped_config(), o, dir / "zero.csv", dir / "zero.json");
  EXPECT_EQ(slurp(dir / "fixed.csv"), slurp(dir / "zero.csv"));
  return fixed;
}

// The step-to-step tissue variation draws its factors only when asked for: without it the session
// keeps its bytes and every factor is 1; with it the factors' logarithms scatter by the SD asked
// for, and the peak forces follow them.
TEST(Simulator, TissueStepVariationScattersKbarAndCbarByTheSdAskedFor) {
  const auto dir = test::scratch_dir("sim-step-sd");
  SimulationOptions o = minute_options();
  const SimulationTruth fixed =
      simulate_kept_by_zero(dir, o, [](SimulationOptions& z) { z.tissue_step_sd_pct = 0.0; });
  for (const SimulatedStep& step : fixed.steps) {
    for (Region r : kRegions) {
      EXPECT_EQ(step.kbar_factor[index_of(r)], 1.0);
      EXPECT_EQ(step.cbar_factor[index_of(r)], 1.0);
    }
  }

  o.tissue_step_sd_pct = 20.0;
  const SimulationTruth varied =
      simulate_session(shipped_config(), o, dir / "varied.csv", dir / "varied.json");
  ASSERT_EQ(varied.steps.size(), fixed.steps.size());
  std::vector<double> log_k, log_c;
  const std::size_t heel = index_of(Region::Heel);
  for (std::size_t i = 0; i < varied.steps.size(); ++i) {
    const SimulatedStep& step = varied.steps[i];
    for (Region r : kRegions) {
      log_k.push_back(std::log(step.kbar_factor[index_of(r)]));
      log_c.push_back(std::log(step.cbar_factor[index_of(r)]));
    }
    if (step.partial || fixed.steps[i].partial) continue;
    // The heel's contact area keeps its course, so its peak force, elastic plus damping, scales
    // by a mix of the two factors (the peak's frame may move a little).
    const double ratio = step.peak_force_n[heel] / fixed.steps[i].peak_force_n[heel];
    const auto [lo, hi] = std::minmax(step.kbar_factor[heel], step.cbar_factor[heel]);
    EXPECT_GE(ratio, 0.98 * lo) << i;
    EXPECT_LE(ratio, 1.02 * hi) << i;
  }
  const auto& sd = test::sample_sd;
  ASSERT_GE(log_k.size(), 500u);
  EXPECT_NEAR(sd(log_k), 0.20, 0.02);
  EXPECT_NEAR(sd(log_c), 0.20, 0.02);
  const nlohmann::json truth = nlohmann::json::parse(slurp(dir / "varied.json"));
  EXPECT_EQ(truth["options"]["tissue_step_sd_pct"].get<double>(), 20.0);
  const auto first_left = std::find_if(varied.steps.begin(), varied.steps.end(),
                                       [](const SimulatedStep& s) { return s.foot == Foot::Left; });
  ASSERT_NE(first_left, varied.steps.end());
  const nlohmann::json& factors = truth["steps"]["L"][0]["tissue_factors"]["heel"];
  EXPECT_EQ(factors["kbar"].get<double>(), first_left->kbar_factor[heel]);
  EXPECT_EQ(factors["cbar"].get<double>(), first_left->cbar_factor[heel]);
}

// A tissue drift multiplies each stance's kbar and cbar by (1 + pct / 100) to the power of its
// start in minutes, and at 0 keeps every byte.
TEST(Simulator, TissueDriftScalesEachStanceByItsStartTime) {
  const auto dir = test::scratch_dir("sim-drift");
  SimulationOptions o = minute_options();
  simulate_kept_by_zero(dir, o, [](SimulationOptions& z) { z.tissue_drift_pct_per_min = 0.0; });
  o.tissue_drift_pct_per_min = -10.0;
  const SimulationTruth drifting =
      simulate_session(shipped_config(), o, dir / "drift.csv", dir / "drift.json");
  ASSERT_GE(drifting.steps.size(), 100u);
  for (const SimulatedStep& step : drifting.steps) {
    const double expected = std::pow(0.9, step.t_contact_start_s / 60.0);
    for (Region r : kRegions) {
      EXPECT_NEAR(step.kbar_factor[index_of(r)], expected, 1e-12);
      EXPECT_NEAR(step.cbar_factor[index_of(r)], expected, 1e-12);
    }
  }
  EXPECT_LT(drifting.steps.back().kbar_factor[0], 0.92);
  const nlohmann::json truth = nlohmann::json::parse(slurp(dir / "drift.json"));
  EXPECT_EQ(truth["options"]["tissue_drift_pct_per_min"].get<double>(), -10.0);
  EXPECT_TRUE(truth["steps"]["L"][0].contains("tissue_factors"));
}

// A difference between the feet scales every right-foot stance's kbar and cbar and no left one;
// without it the session keeps its bytes. The right foot's peak forces follow the factor.
TEST(Simulator, TissueAsymmetryScalesTheRightFootsStances) {
  const auto dir = test::scratch_dir("sim-asymmetry");
  SimulationOptions o = minute_options();
  const SimulationTruth even =
      simulate_kept_by_zero(dir, o, [](SimulationOptions& z) { z.tissue_asymmetry_pct = 0.0; });
  o.tissue_asymmetry_pct = 20.0;
  const SimulationTruth uneven =
      simulate_session(shipped_config(), o, dir / "uneven.csv", dir / "uneven.json");
  ASSERT_EQ(uneven.steps.size(), even.steps.size());
  std::array<int, 2> feet{};
  for (std::size_t i = 0; i < uneven.steps.size(); ++i) {
    const SimulatedStep& step = uneven.steps[i];
    const double expected = step.foot == Foot::Right ? 1.2 : 1.0;
    ++feet[static_cast<std::size_t>(step.foot)];
    for (Region r : kRegions) {
      EXPECT_DOUBLE_EQ(step.kbar_factor[index_of(r)], expected);
      EXPECT_DOUBLE_EQ(step.cbar_factor[index_of(r)], expected);
    }
    if (!step.partial && step.foot == Foot::Right) {
      EXPECT_GT(step.peak_force_n[0], 1.1 * even.steps[i].peak_force_n[0]);
    }
  }
  EXPECT_GE(feet[0], 40);
  EXPECT_GE(feet[1], 40);
  const nlohmann::json truth = nlohmann::json::parse(slurp(dir / "uneven.json"));
  EXPECT_EQ(truth["options"]["tissue_asymmetry_pct"].get<double>(), 20.0);
  EXPECT_TRUE(truth["steps"]["R"][0].contains("tissue_factors"));
}

// The placement shifts are drawn only when asked for: without them the session keeps its bytes;
// with them each stance's offsets scatter by the SD asked for, the same for every region of the
// foot, and the truth JSON records them per step.
TEST(Simulator, PlacementVariationShiftsEachStanceByTheSdAskedFor) {
  const auto dir = test::scratch_dir("sim-placement");
  SimulationOptions o = minute_options();
  const SimulationTruth fixed =
      simulate_kept_by_zero(dir, o, [](SimulationOptions& z) { z.placement_sd_mm = 0.0; });
  for (const SimulatedStep& step : fixed.steps) {
    EXPECT_EQ(step.placement_shift.x_mm, 0.0);
    EXPECT_EQ(step.placement_shift.y_mm, 0.0);
  }
  EXPECT_FALSE(nlohmann::json::parse(slurp(dir / "fixed.json"))["steps"]["L"][0].contains(
      "placement_shift_mm"));

  o.placement_sd_mm = 3.0;
  const SimulationTruth moved =
      simulate_session(shipped_config(), o, dir / "moved.csv", dir / "moved.json");
  ASSERT_EQ(moved.steps.size(), fixed.steps.size());
  EXPECT_NE(slurp(dir / "fixed.csv"), slurp(dir / "moved.csv"));
  std::vector<double> x, y;
  for (const SimulatedStep& step : moved.steps) {
    x.push_back(step.placement_shift.x_mm);
    y.push_back(step.placement_shift.y_mm);
  }
  ASSERT_GE(x.size(), 100u);
  EXPECT_NEAR(test::sample_sd(x), 3.0, 0.5);
  EXPECT_NEAR(test::sample_sd(y), 3.0, 0.5);
  const nlohmann::json truth = nlohmann::json::parse(slurp(dir / "moved.json"));
  EXPECT_EQ(truth["options"]["placement_sd_mm"].get<double>(), 3.0);
  const auto first_right =
      std::find_if(moved.steps.begin(), moved.steps.end(),
                   [](const SimulatedStep& s) { return s.foot == Foot::Right; });
  ASSERT_NE(first_right, moved.steps.end());
  const nlohmann::json& shift = truth["steps"]["R"][0]["placement_shift_mm"];
  EXPECT_EQ(shift["x"].get<double>(), first_right->placement_shift.x_mm);
  EXPECT_EQ(shift["y"].get<double>(), first_right->placement_shift.y_mm);
}

TEST(Simulator, WrittenSessionReadsBackAndTheTruthIsPlausible) {
  const auto dir = test::scratch_dir("sim-readback");
  SimulationOptions o = short_options(11);
  o.duration_s = 15.0;
  o.body_mass_kg = 55.0;
  o.subject = "unit test";
  const SimulationTruth truth =
      simulate_session(shipped_config(), o, dir / "s.csv", dir / "s.json");

  SessionReader reader(dir / "s.csv");
  const SessionHeader& header = reader.header();
  EXPECT_EQ(header.version, 1);
  EXPECT_EQ(header.insole_size, InsoleSize::S37_38);
  EXPECT_EQ(header.sample_rate_hz, 100.0);
  EXPECT_EQ(header.sensors, 107u);
  EXPECT_EQ(header.subject, "unit test");
  EXPECT_EQ(header.body_mass_kg, 55.0);
  EXPECT_EQ(header.note, "SIMULATED by gaitmon simulate (seed 11, model correct)");

  // Summed bits above each sensor's dc bias, per foot and frame.
  std::array<std::vector<double>, 2> summed;
  Frame frame;
  std::int64_t frames = 0;
  int max_bits = 0;
  while (reader.next(frame)) {
    const auto foot = static_cast<std::size_t>(frame.foot);
    EXPECT_EQ(frame.foot, frames % 2 == 0 ? Foot::Left : Foot::Right);
    EXPECT_NEAR(frame.t_s, static_cast<double>(frames / 2) / 100.0, 1e-12);
    double sum = 0.0;
    for (std::size_t s = 0; s < frame.bits.size(); ++s) {
      sum += frame.bits[s] - truth.dc_bias_bits[foot][s];
      max_bits = std::max<int>(max_bits, frame.bits[s]);
    }
    summed[foot].push_back(sum);
    ++frames;
  }
  EXPECT_EQ(frames, 2 * 1500);
  EXPECT_EQ(truth.frames_per_foot, 1500);
  EXPECT_GT(max_bits, 50);
  EXPECT_LT(max_bits, 255);
  EXPECT_EQ(truth.clipped_high_samples, 0u);
  EXPECT_EQ(truth.negative_force_samples, 0u);

  const double body_weight = 55.0 * 9.80665;
  ASSERT_GE(truth.steps.size(), 24u);
  int complete = 0;
  for (std::size_t i = 0; i < truth.steps.size(); ++i) {
    const SimulatedStep& step = truth.steps[i];
    if (i > 0) {
      EXPECT_NE(step.foot, truth.steps[i - 1].foot) << "step " << i;
    }
    if (step.partial) {
      EXPECT_TRUE(i < 2 || i + 2 >= truth.steps.size()) << "partial step " << i << " mid-file";
      continue;
    }
    ++complete;
    const double stance = step.t_toe_off_s - step.t_heel_strike_s;
    EXPECT_GE(stance, 0.5) << "step " << i;
    EXPECT_LE(stance, 0.9) << "step " << i;
    EXPECT_GE(step.peak_total_force_n, 0.8 * body_weight) << "step " << i;
    EXPECT_LE(step.peak_total_force_n, 1.6 * body_weight) << "step " << i;
    EXPECT_GT(step.peak_force_n[index_of(Region::Heel)], 0.3 * body_weight);
    EXPECT_GT(step.peak_force_n[index_of(Region::Met3_5)], 0.3 * body_weight);
    // The file agrees with the events: 142 bits (40 N) is crossed at heel strike and toe off,
    // up to the noise (0.5 bit SD on 107 sensors, ~5 bits).
    const auto& sums = summed[static_cast<std::size_t>(step.foot)];
    const auto hs = static_cast<std::size_t>(step.heel_strike_frame);
    const auto to = static_cast<std::size_t>(step.toe_off_frame);
    EXPECT_LT(sums[hs - 2], 142.0) << "step " << i;
    EXPECT_GT(sums[hs + 2], 142.0) << "step " << i;
    EXPECT_GT(sums[to - 2], 142.0) << "step " << i;
    EXPECT_LT(sums[to + 2], 142.0) << "step " << i;
    EXPECT_GT(sums[(hs + to) / 2], 0.25 * body_weight / truth.newtons_per_bit);
  }
  EXPECT_GE(complete, 22);
}

TEST(Simulator, TruthJsonRecordsParametersAndSteps) {
  const auto dir = test::scratch_dir("sim-truth");
  SimulationOptions o = short_options(3);
  EllipsoidParams heel = seed_means(Region::Heel);
  heel.kbar_n_per_mm3 = 0.2;
  o.region_params[index_of(Region::Heel)] = heel;
  o.rasterisation = Rasterisation::Coverage;
  const SimulationTruth truth =
      simulate_session(shipped_config(), o, dir / "s.csv", dir / "s.json");
  std::ifstream in(dir / "s.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j.at("simulated"), true);
  EXPECT_EQ(j.at("model"), "correct");
  EXPECT_EQ(j.at("rasterisation"), "coverage");
  EXPECT_EQ(j.at("options").at("seed"), 3);
  EXPECT_EQ(j.at("options").at("insole_size"), "37-38");
  EXPECT_NEAR(j.at("event_threshold_n").get<double>(), 142 * 64.0 / 255.0 * 1.125, 1e-9);
  EXPECT_EQ(j.at("regions").size(), kRegionCount);
  EXPECT_EQ(j.at("regions").at("heel").at("kbar_n_per_mm3"), 0.2);
  EXPECT_EQ(j.at("regions").at("met3_5").at("A_mm"), 139.7);  // Appendix I, 37-38
  EXPECT_EQ(j.at("regions").at("toe2").at("m"), 1.11);
  for (const char* key :
       {"A_mm", "B_mm", "C_mm", "d0_mm", "kbar_n_per_mm3", "n", "cbar_ns_per_mm3", "m"}) {
    EXPECT_TRUE(j.at("regions").at("toe1").contains(key)) << key;
  }
  std::size_t steps = 0;
  for (const char* foot : {"L", "R"}) {
    EXPECT_EQ(j.at("dc_bias_bits").at(foot).size(), 107u);
    for (const auto& step : j.at("steps").at(foot)) {
      EXPECT_EQ(step.at("t_heel_strike_s").get<double>(),
                step.at("heel_strike_frame").get<double>() / 100.0);
      EXPECT_TRUE(step.at("peak_force_n").contains("toes3_5"));
      ++steps;
    }
  }
  EXPECT_EQ(steps, truth.steps.size());
}

TEST(Simulator, SeedSignWithHeavyDampingClampsNegativeForcesAndSaysSo) {
  const auto dir = test::scratch_dir("sim-seed-sign");
  SimulationOptions o = short_options(5);
  o.model = ModelVariant::SeedEq25;
  for (Region r : kRegions) {
    EllipsoidParams p = seed_means(r);
    p.cbar_ns_per_mm3 *= 300.0;
    o.region_params[index_of(r)] = p;
  }
  const SimulationTruth truth =
      simulate_session(shipped_config(), o, dir / "s.csv", dir / "s.json");
  EXPECT_GT(truth.negative_force_samples, 0u);
  std::ifstream in(dir / "s.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j.at("negative_force_samples").get<std::uint64_t>(), truth.negative_force_samples);
  EXPECT_EQ(j.at("model"), "seed_eq25");
}

TEST(Simulator, RejectsBadOptions) {
  const auto dir = test::scratch_dir("sim-bad");
  const auto run = [&](const SimulationOptions& o) {
    simulate_session(shipped_config(), o, dir / "s.csv", dir / "s.json");
  };
  SimulationOptions o = short_options(1);
  o.duration_s = 0.0;
  EXPECT_THROW(run(o), std::invalid_argument);
  o = short_options(1);
  o.timing.stance_fraction = 0.95;
  EXPECT_THROW(run(o), std::invalid_argument);
  o = short_options(1);
  o.effects = {"creep"};
  EXPECT_THROW(run(o), std::invalid_argument);
  o = short_options(1);
  EllipsoidParams soft = seed_means(Region::Heel);
  soft.kbar_n_per_mm3 = -0.1;
  o.region_params[index_of(Region::Heel)] = soft;
  EXPECT_THROW(run(o), std::invalid_argument);
  o = short_options(1);
  o.tissue_step_sd_pct = 101.0;
  EXPECT_THROW(run(o), std::invalid_argument);
  o = short_options(1);
  o.placement_sd_mm = 10.5;
  EXPECT_THROW(run(o), std::invalid_argument);
  o = short_options(1);
  o.tissue_drift_pct_per_min = -21.0;
  EXPECT_THROW(run(o), std::invalid_argument);
  o = short_options(1);
  o.tissue_asymmetry_pct = -50.5;
  EXPECT_THROW(run(o), std::invalid_argument);
  o = short_options(1);
  o.min_bias_bits = 3;
  o.max_bias_bits = 2;
  EXPECT_THROW(run(o), std::invalid_argument);
  o = short_options(1);
  o.min_bias_bits = -1;
  EXPECT_THROW(run(o), std::invalid_argument);
  o = short_options(1);
  EllipsoidParams flat = seed_means(Region::Toe1);
  flat.C_mm = 0.0;
  o.region_params[index_of(Region::Toe1)] = flat;
  EXPECT_THROW(run(o), std::invalid_argument);
}

// Each cell's dc bias is drawn from min..max. With the default 0-2 bits a third of the cells sit
// at 0 and read their noise clipped there in the swing; from 3 bits up (six noise SDs) none does.
TEST(Simulator, DcBiasIsDrawnFromMinToMax) {
  const auto dir = test::scratch_dir("sim-bias");
  SimulationOptions o = short_options(3);
  const SimulationTruth floor =
      simulate_session(shipped_config(), o, dir / "a.csv", dir / "a.json");
  o.min_bias_bits = 3;
  o.max_bias_bits = 5;
  const SimulationTruth above =
      simulate_session(shipped_config(), o, dir / "b.csv", dir / "b.json");
  for (const auto& bias : above.dc_bias_bits) {
    for (int b : {3, 4, 5}) EXPECT_NE(std::find(bias.begin(), bias.end(), b), bias.end()) << b;
    for (int b : bias) {
      EXPECT_GE(b, 3);
      EXPECT_LE(b, 5);
    }
  }
  EXPECT_GT(floor.clipped_low_samples, 0u);
  EXPECT_EQ(above.clipped_low_samples, 0u);
  const nlohmann::json j = nlohmann::json::parse(test::read_text(dir / "b.json"));
  EXPECT_EQ(j.at("options").at("min_bias_bits"), 3);
  EXPECT_EQ(j.at("options").at("max_bias_bits"), 5);
}

TEST(Simulator, RasterisationNames) {
  EXPECT_EQ(rasterisation_name(Rasterisation::CellCentre), "centre");
  EXPECT_EQ(rasterisation_name(Rasterisation::Coverage), "coverage");
  EXPECT_EQ(parse_rasterisation("centre"), Rasterisation::CellCentre);
  EXPECT_EQ(parse_rasterisation("coverage"), Rasterisation::Coverage);
  EXPECT_EQ(parse_rasterisation("center"), std::nullopt);
}

}  // namespace
}  // namespace gaitmon
