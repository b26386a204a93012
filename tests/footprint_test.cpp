// Tests of the load-fitted footprint: exact on a sampled paraboloid, close to the model's own
// contact area on its pressure field, exact on two rows given the aspect, and nullopt wherever
// the cells cannot determine it or a cell that reads nothing contradicts it.
#include "gaitmon/footprint.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
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
// Where the cells span three rows and three columns the aspect is theirs and this one is unused.
constexpr double kAnyAspect = 1.0;

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

TEST(Footprint, ExactOnASampledParaboloid) {
  // Off-centre against the lattice, so no symmetry helps.
  const double rA = 24.3;
  const double rB = 41.7;
  const auto cells = sampled_cap(31.1, 52.4, rA, rB, 87.0, 9, 8);
  ASSERT_GE(cells.size(), 10u);
  const auto area = footprint_area_mm2(cells, CellSize{kW, kH}, kAnyAspect);
  ASSERT_TRUE(area.has_value());
  EXPECT_NEAR(*area, kPi * rA * rB, 1e-9 * kPi * rA * rB);
}

TEST(Footprint, IndependentOfTheLoadUnit) {
  auto cells = sampled_cap(30.0, 45.0, 20.0, 35.0, 50.0, 9, 7);
  const auto in_bits = footprint_area_mm2(cells, CellSize{kW, kH}, kAnyAspect);
  for (LoadedCell& c : cells) c.load *= 0.2824;
  const auto in_newtons = footprint_area_mm2(cells, CellSize{kW, kH}, kAnyAspect);
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
    const auto area = footprint_area_mm2(cells, CellSize{kW, kH}, kAnyAspect);
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
  const auto area = footprint_area_mm2(cells, CellSize{kW, kH}, rA / rB);
  ASSERT_TRUE(area.has_value());
  EXPECT_NEAR(*area, kPi * rA * rB, 1e-9 * kPi * rA * rB);
  const auto wrong = footprint_area_mm2(cells, CellSize{kW, kH}, 0.5 * rA / rB);
  ASSERT_TRUE(wrong.has_value());
  EXPECT_GT(std::abs(*wrong / (kPi * rA * rB) - 1.0), 0.1);
}

TEST(Footprint, OneRowOrTooFewCellsDoNotDetermineIt) {
  EXPECT_FALSE(footprint_area_mm2(sampled_cap(31.0, 0.0, 40.0, 12.0, 60.0, 9, 1), CellSize{kW, kH},
                                  40.0 / 12.0)
                   .has_value());
  auto cells = sampled_cap(30.0, 45.0, 20.0, 35.0, 50.0, 9, 7);
  cells.resize(3);
  EXPECT_FALSE(footprint_area_mm2(cells, CellSize{kW, kH}, kAnyAspect).has_value());
  EXPECT_FALSE(footprint_area_mm2({}, CellSize{kW, kH}, kAnyAspect).has_value());
}

TEST(Footprint, APlateauOrABowlIsNotACap) {
  auto cells = sampled_cap(30.0, 45.0, 20.0, 35.0, 50.0, 9, 7);
  for (LoadedCell& c : cells) c.load = 255.0;  // saturated
  EXPECT_FALSE(footprint_area_mm2(cells, CellSize{kW, kH}, kAnyAspect).has_value());
  for (LoadedCell& c : cells)
    c.load = 1.0 + std::pow(c.x_mm - 30.0, 2) + std::pow(c.y_mm - 45.0, 2);
  EXPECT_FALSE(footprint_area_mm2(cells, CellSize{kW, kH}, kAnyAspect).has_value());
}

TEST(Footprint, AnAreaFarFromTheActiveSensorAreaIsRejected) {
  // A nearly flat cap over 6 x 5 cells extrapolates to an ellipse many times their area.
  auto cells = sampled_cap(22.5, 30.0, 400.0, 600.0, 50.0, 6, 5);
  ASSERT_EQ(cells.size(), 30u);
  EXPECT_FALSE(footprint_area_mm2(cells, CellSize{kW, kH}, kAnyAspect).has_value());
}

// A cell that reads nothing where the fitted cap puts half its peak pressure contradicts the
// fit; one outside the cap, or on its rim, does not.
TEST(Footprint, ACapOverACellThatReadsNothingIsRejected) {
  const double cx = 30.0, cy = 45.0, rA = 20.0, rB = 35.0;
  const auto cells = sampled_cap(cx, cy, rA, rB, 50.0, 9, 7);
  const auto free = footprint_area_mm2(cells, CellSize{kW, kH}, kAnyAspect);
  ASSERT_TRUE(free.has_value());
  const std::vector<CellCentre> outside{{cx + 1.2 * rA, cy}, {cx, cy - 1.1 * rB}};
  const auto with_outside = footprint_area_mm2(cells, CellSize{kW, kH}, kAnyAspect, outside);
  ASSERT_TRUE(with_outside.has_value());
  EXPECT_EQ(*with_outside, *free);
  // rho^2 = 0.9: a tenth of the peak, within the margin the rim's noisy cells need.
  const std::vector<CellCentre> rim{{cx + std::sqrt(0.9) * rA, cy}};
  EXPECT_TRUE(footprint_area_mm2(cells, CellSize{kW, kH}, kAnyAspect, rim).has_value());
  // rho^2 = 0.5: half the peak.
  const std::vector<CellCentre> inside{{cx, cy + std::sqrt(0.5) * rB}};
  EXPECT_FALSE(footprint_area_mm2(cells, CellSize{kW, kH}, kAnyAspect, inside).has_value());
}

TEST(Footprint, NonFiniteCellsGiveNothing) {
  auto cells = sampled_cap(30.0, 45.0, 20.0, 35.0, 50.0, 9, 7);
  cells[3].load = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(footprint_area_mm2(cells, CellSize{kW, kH}, kAnyAspect).has_value());
  cells[3].load = 1.0;
  cells[5].x_mm = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(footprint_area_mm2(cells, CellSize{kW, kH}, kAnyAspect).has_value());
}

TEST(Footprint, ABadCellSizeOrAspectThrows) {
  const auto cells = sampled_cap(30.0, 45.0, 20.0, 35.0, 50.0, 9, 7);
  EXPECT_THROW((void)footprint_area_mm2(cells, CellSize{0.0, kH}, kAnyAspect),
               std::invalid_argument);
  EXPECT_THROW((void)footprint_area_mm2(cells, CellSize{kW, std::nan("")}, kAnyAspect),
               std::invalid_argument);
  EXPECT_THROW((void)footprint_area_mm2(cells, CellSize{kW, kH}, 0.0), std::invalid_argument);
  EXPECT_THROW((void)footprint_area_mm2(cells, CellSize{kW, kH}, std::nan("")),
               std::invalid_argument);
}

}  // namespace
}  // namespace gaitmon
