// Tests of the load-fitted footprint: exact on a sampled paraboloid, close to the model's own
// contact area on its pressure field, exact on two rows given the aspect, and nullopt wherever
// the cells cannot determine it or a cell that reads nothing contradicts it.
#include "gaitmon/footprint.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <optional>
#include <random>
#include <span>
#include <stdexcept>
#include <vector>

#include "gaitmon/config.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/simulator.hpp"
#include "gaitmon/tissue_model.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

constexpr double kW = 7.5;
constexpr double kH = 15.0;
constexpr double kPi = std::numbers::pi;

/// p = peak (1 - rho^2) of an axis-aligned ellipse sampled at the centres of a cols x rows grid,
/// keeping the cells where it is positive, as the adaptive threshold keeps the loaded ones.
std::vector<LoadedCell> sampled_cap(double cx, double cy, double rA, double rB, double peak,
                                    int cols, int rows) {
  std::vector<LoadedCell> cells;
  for (int j = 0; j < rows; ++j) {
    for (int i = 0; i < cols; ++i) {
      const double x = i * kW;
      const double y = j * kH;
      const double rho2 = std::pow((x - cx) / rA, 2) + std::pow((y - cy) / rB, 2);
      if (rho2 < 1.0) cells.push_back({x, y, peak * (1.0 - rho2)});
    }
  }
  return cells;
}

/// The free fit's area, where it is a cap.
std::optional<double> free_area(std::span<const LoadedCell> cells,
                                std::span<const CellCentre> unloaded = {}) {
  const auto f = free_footprint(cells, CellSize{kW, kH}, unloaded);
  return f ? std::optional<double>(f->area_mm2) : std::nullopt;
}

TEST(Footprint, ExactOnASampledParaboloid) {
  // Off-centre against the lattice, so no symmetry helps.
  const double rA = 24.3;
  const double rB = 41.7;
  const auto cells = sampled_cap(31.1, 52.4, rA, rB, 87.0, 9, 8);
  ASSERT_GE(cells.size(), 10u);
  const auto area = free_area(cells);
  ASSERT_TRUE(area.has_value());
  EXPECT_NEAR(*area, kPi * rA * rB, 1e-9 * kPi * rA * rB);
}

TEST(Footprint, IndependentOfTheLoadUnit) {
  auto cells = sampled_cap(30.0, 45.0, 20.0, 35.0, 50.0, 9, 7);
  const auto in_bits = free_area(cells);
  for (LoadedCell& c : cells) c.load *= 0.2824;
  const auto in_newtons = free_area(cells);
  ASSERT_TRUE(in_bits && in_newtons);
  EXPECT_NEAR(*in_bits, *in_newtons, 1e-9 * *in_bits);
}

// The derivation's premise, checked on the model itself: the simulator's cell-centre raster of
// eqs 14-15's pressure at a heel contact (g = d/C ~ 0.04) gives back the model's contact area
// (eq 28) to within the O(g) departure from a paraboloid.
TEST(Footprint, RecoversTheModelsContactAreaFromItsPressureField) {
  const Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  const InsoleLayout layout(config.insole(InsoleSize::S41_42), config.sensor);
  const EllipsoidParams params = config.tissue(InsoleSize::S41_42, Region::Heel).mean;
  for (const double area_mm2 : {1500.0, 2500.0, 3300.0}) {
    const double d = deformation_mm(params, area_mm2);
    const double g = d / params.C_mm;
    const std::vector<double> loads = rasterise_region(
        layout, Region::Heel, params, d, 20.0, ModelVariant::Correct, Rasterisation::CellCentre,
        force_n(params, d, 20.0, ModelVariant::Correct));
    std::vector<LoadedCell> cells;
    const auto& sensors = layout.region_sensors(Region::Heel);
    for (std::size_t i = 0; i < sensors.size(); ++i) {
      if (loads[i] <= 0.0) continue;
      const Sensor& s = layout.sensor(sensors[i]);
      cells.push_back({s.grid_x_mm, s.grid_y_mm, loads[i]});
    }
    const auto area = free_area(cells);
    ASSERT_TRUE(area.has_value()) << "area " << area_mm2;
    EXPECT_LT(g, 0.06);
    EXPECT_NEAR(*area / area_mm2, 1.0, g) << "area " << area_mm2 << ", g " << g;
  }
}

// A two-row midfoot: the anterior-posterior curvature is not seen, so the aspect must be given.
// With the true one the area is exact; with a wrong one it is wrong, which is the prior's cost.
TEST(Footprint, TwoRowsDetermineItWithTheAspect) {
  const double rA = 40.0;
  const double rB = 12.0;
  const auto cells = sampled_cap(31.0, 7.5, rA, rB, 60.0, 9, 2);
  ASSERT_GE(cells.size(), 8u);
  const auto area = footprint_area_at_aspect_mm2(cells, CellSize{kW, kH}, rA / rB);
  ASSERT_TRUE(area.has_value());
  EXPECT_NEAR(*area, kPi * rA * rB, 1e-9 * kPi * rA * rB);
  const auto wrong = footprint_area_at_aspect_mm2(cells, CellSize{kW, kH}, 0.5 * rA / rB);
  ASSERT_TRUE(wrong.has_value());
  EXPECT_GT(std::abs(*wrong / (kPi * rA * rB) - 1.0), 0.1);
}

TEST(Footprint, TheFreeFitGivesTheAspectAndThePeak) {
  const double rA = 24.3;
  const double rB = 41.7;
  const auto fit = free_footprint(sampled_cap(31.1, 52.4, rA, rB, 87.0, 9, 8), CellSize{kW, kH});
  ASSERT_TRUE(fit.has_value());
  EXPECT_NEAR(fit->aspect, rA / rB, 1e-9);
  EXPECT_NEAR(fit->peak, 87.0, 1e-9);
  EXPECT_NEAR(fit->area_mm2, kPi * rA * rB, 1e-9 * kPi * rA * rB);
}

TEST(Footprint, TheSharedAspectIsTheLogMeanWeightedByThePeakSquared) {
  EXPECT_FALSE(shared_aspect({}).has_value());
  // Equal peaks: the geometric mean of 1 and 4.
  const std::vector<Footprint> equal{{100.0, 1.0, 5.0}, {100.0, 4.0, 5.0}};
  EXPECT_NEAR(*shared_aspect(equal), 2.0, 1e-12);
  // Peaks 3 and 1: weights 9 and 1, so exp(0.1 ln 4).
  const std::vector<Footprint> weighted{{100.0, 1.0, 3.0}, {100.0, 4.0, 1.0}};
  EXPECT_NEAR(*shared_aspect(weighted), std::pow(4.0, 0.1), 1e-12);
  // Fits without a usable aspect or peak do not count.
  const std::vector<Footprint> with_bad{
      {100.0, 2.5, 7.0}, {100.0, 0.0, 7.0}, {100.0, 9.0, 0.0}, {100.0, std::nan(""), 7.0}};
  EXPECT_NEAR(*shared_aspect(with_bad), 2.5, 1e-12);
}

// Why measure_stance shares the aspect: met1_2 of size 45-46 (22 cells) as the simulator
// rasterises it, with 0.5-bit noise, rounding and a 6-bit threshold, at half its peak area. The
// free fit takes its curvature ratio from the few loaded cells and scatters by about 10 %; at
// the aspect that 20 full-load frames share it scatters by under 3 %, without a bias.
TEST(Footprint, AtTheSharedAspectAPartialLoadScattersLessThanAlone) {
  const Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  const InsoleSize size = InsoleSize::S45_46;
  const InsoleLayout layout(config.insole(size), config.sensor);
  const Region region = Region::Met1_2;
  const EllipsoidParams params = config.tissue(size, region).mean;
  const auto& sensors = layout.region_sensors(region);
  const CellSize cell{config.sensor.width_mm, config.sensor.height_mm};
  const double bits_per_n = 1.0 / config.calibration.newtons_per_bit(config.sensor.area_mm2());
  const double peak_area = 0.69 * static_cast<double>(sensors.size()) * config.sensor.area_mm2();
  std::mt19937_64 rng(7);
  std::normal_distribution<double> noise(0.0, 0.5);
  const auto frame = [&](double area_mm2, std::vector<LoadedCell>& loaded,
                         std::vector<CellCentre>& unloaded) {
    const double d = deformation_mm(params, area_mm2);
    const std::vector<double> loads =
        rasterise_region(layout, region, params, d, 0.0, ModelVariant::Correct,
                         Rasterisation::CellCentre, force_n(params, d, 0.0, ModelVariant::Correct));
    loaded.clear();
    unloaded.clear();
    for (std::size_t i = 0; i < sensors.size(); ++i) {
      const Sensor& s = layout.sensor(sensors[i]);
      const double bits = std::clamp(std::round(loads[i] * bits_per_n + noise(rng)), 0.0, 255.0);
      if (bits < 6.0) {
        unloaded.push_back({s.grid_x_mm, s.grid_y_mm});
      } else {
        loaded.push_back({s.grid_x_mm, s.grid_y_mm, bits});
      }
    }
  };
  std::vector<LoadedCell> loaded;
  std::vector<CellCentre> unloaded;
  std::vector<Footprint> full_load;
  for (int k = 0; k < 20; ++k) {
    frame(peak_area, loaded, unloaded);
    if (const auto f = free_footprint(loaded, cell, unloaded)) full_load.push_back(*f);
  }
  const auto aspect = shared_aspect(full_load);
  ASSERT_TRUE(aspect.has_value());
  std::vector<double> alone, shared;
  for (int k = 0; k < 300; ++k) {
    frame(0.5 * peak_area, loaded, unloaded);
    if (const auto f = free_footprint(loaded, cell, unloaded)) {
      alone.push_back(f->area_mm2 / (0.5 * peak_area));
    }
    if (const auto a = footprint_area_at_aspect_mm2(loaded, cell, *aspect, unloaded)) {
      shared.push_back(*a / (0.5 * peak_area));
    }
  }
  const auto mean_sd = [](const std::vector<double>& v) {
    double m = 0.0;
    for (double x : v) m += x / static_cast<double>(v.size());
    double ss = 0.0;
    for (double x : v) ss += (x - m) * (x - m);
    return std::pair{m, std::sqrt(ss / static_cast<double>(v.size()))};
  };
  ASSERT_GE(alone.size(), 200u);
  ASSERT_EQ(shared.size(), 300u);
  const auto [alone_mean, alone_sd] = mean_sd(alone);
  const auto [shared_mean, shared_sd] = mean_sd(shared);
  std::printf(
      "met1_2 at half its area: alone %.3f +- %.3f (%zu fits), shared aspect %.3f +- %.3f\n",
      alone_mean, alone_sd, alone.size(), shared_mean, shared_sd);
  EXPECT_GT(alone_sd, 0.06);
  EXPECT_LT(shared_sd, 0.03);
  EXPECT_NEAR(shared_mean, 1.0, 0.01);
}

TEST(Footprint, OneRowOrTooFewCellsDoNotDetermineIt) {
  EXPECT_FALSE(footprint_area_at_aspect_mm2(sampled_cap(31.0, 0.0, 40.0, 12.0, 60.0, 9, 1),
                                            CellSize{kW, kH}, 40.0 / 12.0)
                   .has_value());
  auto cells = sampled_cap(30.0, 45.0, 20.0, 35.0, 50.0, 9, 7);
  cells.resize(3);
  EXPECT_FALSE(free_area(cells).has_value());
  EXPECT_FALSE(free_area({}).has_value());
}

TEST(Footprint, APlateauOrABowlIsNotACap) {
  auto cells = sampled_cap(30.0, 45.0, 20.0, 35.0, 50.0, 9, 7);
  for (LoadedCell& c : cells) c.load = 255.0;  // saturated
  EXPECT_FALSE(free_area(cells).has_value());
  for (LoadedCell& c : cells)
    c.load = 1.0 + std::pow(c.x_mm - 30.0, 2) + std::pow(c.y_mm - 45.0, 2);
  EXPECT_FALSE(free_area(cells).has_value());
}

TEST(Footprint, AnAreaFarFromTheActiveSensorAreaIsRejected) {
  // A nearly flat cap over 6 x 5 cells extrapolates to an ellipse many times their area.
  auto cells = sampled_cap(22.5, 30.0, 400.0, 600.0, 50.0, 6, 5);
  ASSERT_EQ(cells.size(), 30u);
  EXPECT_FALSE(free_area(cells).has_value());
}

// A cell that reads nothing where the fitted cap puts half its peak pressure contradicts the
// fit; one outside the cap, or on its rim, does not.
TEST(Footprint, ACapOverACellThatReadsNothingIsRejected) {
  const double cx = 30.0, cy = 45.0, rA = 20.0, rB = 35.0;
  const auto cells = sampled_cap(cx, cy, rA, rB, 50.0, 9, 7);
  const auto free = free_area(cells);
  ASSERT_TRUE(free.has_value());
  const std::vector<CellCentre> outside{{cx + 1.2 * rA, cy}, {cx, cy - 1.1 * rB}};
  const auto with_outside = free_area(cells, outside);
  ASSERT_TRUE(with_outside.has_value());
  EXPECT_EQ(*with_outside, *free);
  // rho^2 = 0.9: a tenth of the peak, within the margin the rim's noisy cells need.
  const std::vector<CellCentre> rim{{cx + std::sqrt(0.9) * rA, cy}};
  EXPECT_TRUE(free_area(cells, rim).has_value());
  // rho^2 = 0.5: half the peak.
  const std::vector<CellCentre> inside{{cx, cy + std::sqrt(0.5) * rB}};
  EXPECT_FALSE(free_area(cells, inside).has_value());
}

TEST(Footprint, NonFiniteCellsGiveNothing) {
  auto cells = sampled_cap(30.0, 45.0, 20.0, 35.0, 50.0, 9, 7);
  cells[3].load = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(free_area(cells).has_value());
  cells[3].load = 1.0;
  cells[5].x_mm = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(free_area(cells).has_value());
}

TEST(Footprint, ABadCellSizeOrAspectThrows) {
  const auto cells = sampled_cap(30.0, 45.0, 20.0, 35.0, 50.0, 9, 7);
  EXPECT_THROW((void)free_footprint(cells, CellSize{0.0, kH}), std::invalid_argument);
  EXPECT_THROW((void)free_footprint(cells, CellSize{kW, std::nan("")}), std::invalid_argument);
  EXPECT_THROW((void)footprint_area_at_aspect_mm2(cells, CellSize{0.0, kH}, 1.0),
               std::invalid_argument);
  EXPECT_THROW((void)footprint_area_at_aspect_mm2(cells, CellSize{kW, kH}, 0.0),
               std::invalid_argument);
  EXPECT_THROW((void)footprint_area_at_aspect_mm2(cells, CellSize{kW, kH}, std::nan("")),
               std::invalid_argument);
}

}  // namespace
}  // namespace gaitmon
