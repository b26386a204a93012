// Per-region force, area and ellipse of a hand-made stance on the shipped 37-38 layout, and what
// simulated steps say of how their cells read.
#include "gaitmon/stance.hpp"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include "gaitmon/batch.hpp"
#include "gaitmon/crosstalk.hpp"
#include "gaitmon/simulator.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

class StanceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    config_ = load_config(test::source_dir() / "config" / "gaitmon.toml");
    layout_.emplace(config_.insole(InsoleSize::S37_38), config_.sensor);
  }

  /// A step whose zero is 2 bits on every sensor and whose threshold is 5 bits.
  Step make_step(const std::vector<std::vector<std::uint8_t>>& frames) const {
    Step step;
    step.sensor_zero_bits.assign(layout_->sensor_count(), 2.0);
    step.adaptive_threshold_bits = 5.0;
    for (std::size_t i = 0; i < frames.size(); ++i) {
      step.stance.push_back({0.01 * static_cast<double>(i), Foot::Left, frames[i]});
    }
    return step;
  }

  /// Sensor index (0-based) of row `row`, number `number` (1-based, Appendix B form).
  std::size_t sensor_at(int row, int number) const {
    for (const Sensor& s : layout_->sensors()) {
      if (s.row == row && s.number_in_row == number) return s.index;
    }
    ADD_FAILURE() << "no sensor at row " << row << " number " << number;
    return 0;
  }

  Config config_;
  std::optional<InsoleLayout> layout_;
};

TEST_F(StanceTest, ForceIsEq42OverActiveSensorsAfterZeroing) {
  // Heel rows 12-13, sensors 2-4 (size 37-38, Appendix B: the heel spans rows 12-15), loaded
  // with 102 raw bits each: 100 bits after the 2-bit zero. One more heel sensor reads 6 raw bits
  // (4 after zeroing, under the 5-bit threshold) and must not count.
  std::vector<std::uint8_t> bits(layout_->sensor_count(), 2);
  for (int row : {12, 13}) {
    for (int number : {2, 3, 4}) bits[sensor_at(row, number)] = 102;
  }
  bits[sensor_at(15, 1)] = 6;
  const StanceSeries series = measure_stance(make_step({bits}), *layout_, config_.calibration);
  ASSERT_EQ(series.size(), 1u);
  const RegionSample& heel = series.at(0, Region::Heel);
  // 6 sensors x 100 bits x (64 N/cm^2 / 255 bits x 1.125 cm^2 = 0.282353 N/bit) = 169.412 N.
  EXPECT_NEAR(heel.force_n, 169.412, 1e-3);
  EXPECT_EQ(heel.active_sensors, 6);
  EXPECT_DOUBLE_EQ(heel.sensor_area_mm2, 675.0);
  // A 3 x 2 block is Case 2: rA = 3 x 7.5 / sqrt(pi) = 12.6943 mm, rB = 2 x 15 / sqrt(pi)
  // = 16.9257 mm, and the ellipse area equals the sensor area.
  EXPECT_EQ(heel.ellipse.kase, EllipseCase::Rectangle);
  EXPECT_NEAR(heel.ellipse.ra_mm, 12.6943, 1e-4);
  EXPECT_NEAR(heel.ellipse.rb_mm, 16.9257, 1e-4);
  EXPECT_NEAR(heel.ellipse.pi, 1.0, 1e-9);
  for (Region r : kRegions) {
    if (r == Region::Heel) continue;
    EXPECT_EQ(series.at(0, r).force_n, 0.0) << region_name(r);
    EXPECT_EQ(series.at(0, r).ellipse.kase, EllipseCase::None) << region_name(r);
  }
  EXPECT_NEAR(series.total_force_n[0], 169.412, 1e-3);
}

TEST_F(StanceTest, IsolatedHeelSensorCountsOnlyAtTheFirstInstantInTheOutermostRow) {
  std::vector<std::uint8_t> bits(layout_->sensor_count(), 2);
  bits[sensor_at(15, 2)] = 52;  // the most posterior row of 37-38 is row 15
  const StanceSeries series =
      measure_stance(make_step({bits, bits}), *layout_, config_.calibration);
  ASSERT_EQ(series.size(), 2u);
  EXPECT_EQ(series.at(0, Region::Heel).ellipse.kase, EllipseCase::Isolated);
  EXPECT_NEAR(series.at(0, Region::Heel).ellipse.pi, 1.0, 1e-9);
  EXPECT_EQ(series.at(1, Region::Heel).ellipse.kase, EllipseCase::None);
  // The force is the sensors' reading either way: Case 1 concerns the contact area only.
  EXPECT_NEAR(series.at(1, Region::Heel).force_n, 50 * 0.2823529, 1e-5);
}

TEST_F(StanceTest, AnEllipseCacheChangesNothing) {
  // An irregular heel pattern (a 3 x 2 block with one more cell) repeated over three frames.
  std::vector<std::uint8_t> bits(layout_->sensor_count(), 2);
  for (int row : {12, 13}) {
    for (int number : {2, 3, 4}) bits[sensor_at(row, number)] = 90;
  }
  bits[sensor_at(14, 3)] = 90;
  const Step step = make_step({bits, bits, bits});
  ContactEllipseCache cache;
  const StanceSeries cached = measure_stance(step, *layout_, config_.calibration, &cache);
  const StanceSeries direct = measure_stance(step, *layout_, config_.calibration);
  ASSERT_EQ(cached.size(), 3u);
  EXPECT_EQ(cached.at(1, Region::Heel).ellipse.kase, EllipseCase::Neighbours);
  for (std::size_t f = 0; f < 3; ++f) {
    const ContactEllipse& a = cached.at(f, Region::Heel).ellipse;
    const ContactEllipse& b = direct.at(f, Region::Heel).ellipse;
    EXPECT_EQ(a.kase, b.kase);
    EXPECT_DOUBLE_EQ(a.area_mm2, b.area_mm2);
    EXPECT_DOUBLE_EQ(a.cx_mm, b.cx_mm);
    EXPECT_DOUBLE_EQ(a.angle_rad, b.angle_rad);
  }
  EXPECT_GE(cache.hits(), 2u);
}

// The footprint of averaging cells is fitted only where asked, and asking changes nothing else.
TEST_F(StanceTest, TheCellMeanFootprintIsFittedOnlyWhereAsked) {
  const auto& heel = layout_->region_sensors(Region::Heel);
  double cx = 0.0, cy = 0.0;
  for (std::size_t i : heel) {
    cx += layout_->sensor(i).grid_x_mm / static_cast<double>(heel.size());
    cy += layout_->sensor(i).grid_y_mm / static_cast<double>(heel.size());
  }
  std::vector<std::uint8_t> bits(layout_->sensor_count(), 2);
  for (std::size_t i : heel) {
    const Sensor& s = layout_->sensor(i);
    const double rho2 =
        std::pow((s.grid_x_mm - cx) / 17.0, 2) + std::pow((s.grid_y_mm - cy) / 28.0, 2);
    if (rho2 < 1.0) bits[i] = static_cast<std::uint8_t>(2.0 + std::round(150.0 * (1 - rho2)));
  }
  const Step step = make_step({bits, bits});
  const StanceSeries skipped = measure_stance(step, *layout_, config_.calibration);
  const StanceSeries fitted =
      measure_stance(step, *layout_, config_.calibration, nullptr, CellMeanFootprint::Fit);
  ASSERT_EQ(fitted.size(), 2u);
  for (std::size_t f = 0; f < 2; ++f) {
    for (Region region : kRegions) {
      EXPECT_FALSE(skipped.at(f, region).footprint_cell_mean_area_mm2.has_value());
      EXPECT_EQ(skipped.at(f, region).footprint_area_mm2, fitted.at(f, region).footprint_area_mm2);
    }
    const auto& area = fitted.at(f, Region::Heel).footprint_cell_mean_area_mm2;
    ASSERT_TRUE(area.has_value());
    // Read at their centres, the cells are not what the fit assumes, but it is a contact of
    // about the cap's size.
    EXPECT_NEAR(*area / (std::numbers::pi * 17.0 * 28.0), 1.0, 0.3);
  }
}

// Two full heel footprints of aspect 0.6 give the stance its aspect; a third frame loads two
// rows only, so its own cells cannot give it, and the heel's box (52.5 x 60 mm, 0.875) would
// give a wrong area. Measured at the shared aspect it has its true area.
TEST_F(StanceTest, AFrameTooSmallForItsOwnAspectTakesTheStancesShared) {
  const auto& heel = layout_->region_sensors(Region::Heel);
  // The heel's first two rows (12 and 13 of size 37-38) share their columns; sensor 4 of row 12
  // sits on the heel's axis.
  const double cx = layout_->sensor(sensor_at(12, 4)).grid_x_mm;
  const double cy_small = 0.5 * (layout_->sensor(sensor_at(12, 4)).grid_y_mm +
                                 layout_->sensor(sensor_at(13, 4)).grid_y_mm);
  double cy_full = 0.0;
  for (std::size_t i : heel)
    cy_full += layout_->sensor(i).grid_y_mm / static_cast<double>(heel.size());
  const double aspect = 0.6;
  const auto cap = [&](double cy, double rB, double peak_bits) {
    std::vector<std::uint8_t> bits(layout_->sensor_count(), 2);
    for (std::size_t i : heel) {
      const Sensor& s = layout_->sensor(i);
      const double rho2 =
          std::pow((s.grid_x_mm - cx) / (aspect * rB), 2) + std::pow((s.grid_y_mm - cy) / rB, 2);
      if (rho2 < 1.0) bits[i] = static_cast<std::uint8_t>(2.0 + std::round(peak_bits * (1 - rho2)));
    }
    return bits;
  };
  // Rows 7.5 mm either side of the centre load, the next ones (22.5 mm) do not; so do the
  // columns 7.5 mm either side (rA = 12 mm) and not the next ones.
  const double rB_small = 20.0;
  const Step step = make_step(
      {cap(cy_full, 28.0, 200.0), cap(cy_full, 28.0, 180.0), cap(cy_small, rB_small, 200.0)});
  const StanceSeries series = measure_stance(step, *layout_, config_.calibration);
  ASSERT_EQ(series.size(), 3u);
  const RegionSample& small = series.at(2, Region::Heel);
  EXPECT_EQ(small.active_sensors, 6);
  EXPECT_FALSE(small.free_footprint.has_value());
  ASSERT_TRUE(small.footprint_area_mm2.has_value());
  const double truth = std::numbers::pi * aspect * rB_small * rB_small;
  EXPECT_NEAR(*small.footprint_area_mm2 / truth, 1.0, 0.02);
  // What the box's aspect would have given from the same cells.
  std::vector<LoadedCell> cells;
  for (std::size_t i : heel) {
    const Sensor& s = layout_->sensor(i);
    const double load = static_cast<double>(step.stance[2].bits[i]) - 2.0;
    if (load >= step.adaptive_threshold_bits) cells.push_back({s.grid_x_mm, s.grid_y_mm, load});
  }
  const CellSize cell{layout_->geometry().width_mm, layout_->geometry().height_mm};
  const auto boxed = footprint_area_at_aspect_mm2(cells, cell, 0.75);
  ASSERT_TRUE(boxed.has_value());
  EXPECT_GT(std::abs(*boxed / truth - 1.0), 0.1);
}

/// A heel cap of `aspect` (rA / rB) about the heel's cells' centroid, `peak_bits` above the
/// zero of 2 bits, and `floor_bits` more on every heel cell, rounded.
std::vector<std::uint8_t> heel_cap(const InsoleLayout& layout, double aspect, double rB,
                                   double peak_bits, double floor_bits = 0.0) {
  const auto& heel = layout.region_sensors(Region::Heel);
  double cx = 0.0, cy = 0.0;
  for (std::size_t i : heel) {
    cx += layout.sensor(i).grid_x_mm / static_cast<double>(heel.size());
    cy += layout.sensor(i).grid_y_mm / static_cast<double>(heel.size());
  }
  std::vector<std::uint8_t> bits(layout.sensor_count(), 2);
  for (std::size_t i : heel) {
    const Sensor& s = layout.sensor(i);
    const double rho2 =
        std::pow((s.grid_x_mm - cx) / (aspect * rB), 2) + std::pow((s.grid_y_mm - cy) / rB, 2);
    const double load = std::max(0.0, peak_bits * (1.0 - rho2)) + floor_bits;
    bits[i] = static_cast<std::uint8_t>(2.0 + std::round(load));
  }
  return bits;
}

/// The heel's zeroed loads in one frame of `step`, all of them or those at or above the
/// threshold.
std::vector<LoadedCell> heel_loads(const Step& step, const InsoleLayout& layout, std::size_t frame,
                                   bool thresholded) {
  std::vector<LoadedCell> cells;
  for (std::size_t i : layout.region_sensors(Region::Heel)) {
    const Sensor& s = layout.sensor(i);
    const double load = static_cast<double>(step.stance[frame].bits[i]) - 2.0;
    if (!thresholded || load >= step.adaptive_threshold_bits) {
      cells.push_back({s.grid_x_mm, s.grid_y_mm, load});
    }
  }
  return cells;
}

/// The aspect the stance's free heel footprints share, as measure_stance takes it.
double heel_shared_aspect(const StanceSeries& series) {
  std::vector<Footprint> fits;
  for (std::size_t f = 0; f < series.size(); ++f) {
    if (const auto& fp = series.at(f, Region::Heel).free_footprint) fits.push_back(*fp);
  }
  return shared_aspect(fits).value();
}

// At toe off the tissue recovers and its pressure falls while the contact is still wide: a heel
// cap of 12 bits at the peak reads under the 5-bit threshold on its outer 40 % of area. The
// stance's footprint is the fit that takes those rim cells in (footprint_area_unthresholded_mm2
// measures what that buys under noise), not the one to the cells above the threshold.
TEST_F(StanceTest, TheRimUnderTheThresholdCountsInTheFootprint) {
  const double aspect = 0.8, rB = 30.0;
  const Step step =
      make_step({heel_cap(*layout_, aspect, rB, 200.0), heel_cap(*layout_, aspect, rB, 12.0)});
  const StanceSeries series = measure_stance(step, *layout_, config_.calibration);
  ASSERT_EQ(series.size(), 2u);
  const CellSize cell{layout_->geometry().width_mm, layout_->geometry().height_mm};
  const double shared = heel_shared_aspect(series);
  const auto above =
      footprint_area_at_aspect_mm2(heel_loads(step, *layout_, 1, true), cell, shared);
  const auto all = footprint_area_unthresholded_mm2(heel_loads(step, *layout_, 1, false), cell,
                                                    shared, step.adaptive_threshold_bits);
  ASSERT_TRUE(above.has_value());
  ASSERT_TRUE(all.has_value());
  EXPECT_GT(std::abs(*all / *above - 1.0), 1e-3);
  ASSERT_TRUE(series.at(1, Region::Heel).footprint_area_mm2.has_value());
  const double fp = *series.at(1, Region::Heel).footprint_area_mm2;
  EXPECT_DOUBLE_EQ(fp, *all);
  // Against the cap's own area, not the code's: the rim fit is the nearer, and near.
  const double truth = std::numbers::pi * aspect * rB * rB;
  std::printf("shared aspect %.3f; footprint %.0f mm2, above the threshold only %.0f, true %.0f\n",
              shared, fp, *above, truth);
  EXPECT_NEAR(shared, aspect, 0.1);
  EXPECT_LT(std::abs(fp / truth - 1.0), std::abs(*above / truth - 1.0));
  EXPECT_LT(std::abs(fp / truth - 1.0), 0.02);  // 0.75 % measured
}

/// `own` (zero 2 bits) with each cell also reading `coupling` times its edge neighbours' share,
/// rounded to bits.
std::vector<std::uint8_t> mixed_readings(const InsoleLayout& layout,
                                         const std::vector<std::uint8_t>& own, double coupling) {
  std::vector<std::uint8_t> mixed(own.size());
  for (std::size_t c = 0; c < own.size(); ++c) {
    double reading = own[c] - 2.0;
    for (const Neighbour& n : layout.neighbours(c)) {
      reading += coupling * n.shared_edge * (own[n.sensor] - 2.0);
    }
    mixed[c] = static_cast<std::uint8_t>(2.0 + std::round(reading));
  }
  return mixed;
}

// Crosstalk of 8 % per edge spreads a heel cap's readings into the ring of cells around it and
// widens the footprint; measured with the correction at that coupling, the stance reads the
// cap's own force and footprint again, to within the rounding of the mixed readings to bits.
TEST_F(StanceTest, UndoingTheCrosstalkGivesBackTheFootprintOfTheCellsOwnReadings) {
  const double coupling = 0.08;
  const std::vector<std::uint8_t> own = heel_cap(*layout_, 0.8, 20.0, 150.0);
  const std::vector<std::uint8_t> mixed = mixed_readings(*layout_, own, coupling);
  const Step plain = make_step({own, own});
  const Step step = make_step({mixed, mixed});
  const CrosstalkCorrection correction(*layout_, coupling);
  const StanceSeries truth = measure_stance(plain, *layout_, config_.calibration);
  const StanceSeries as_read = measure_stance(step, *layout_, config_.calibration);
  const StanceSeries undone = measure_stance(step, *layout_, config_.calibration, nullptr,
                                             CellMeanFootprint::Skip, &correction);
  const RegionSample& t = truth.at(1, Region::Heel);
  const RegionSample& r = as_read.at(1, Region::Heel);
  const RegionSample& u = undone.at(1, Region::Heel);
  ASSERT_TRUE(t.footprint_area_mm2 && r.footprint_area_mm2 && u.footprint_area_mm2);
  std::printf(
      "heel footprint %.0f mm2 own, %.0f with crosstalk, %.0f undone; force %.1f, %.1f, "
      "%.1f N\n",
      *t.footprint_area_mm2, *r.footprint_area_mm2, *u.footprint_area_mm2, t.force_n, r.force_n,
      u.force_n);
  EXPECT_GT(*r.footprint_area_mm2, 1.1 * *t.footprint_area_mm2);
  EXPECT_GT(r.force_n, 1.2 * t.force_n);
  EXPECT_NEAR(*u.footprint_area_mm2 / *t.footprint_area_mm2, 1.0, 0.01);
  // Rounding: half a bit on each cell the readings were mixed into, at most.
  const double newtons_per_bit =
      config_.calibration.newtons_per_bit(layout_->geometry().area_mm2());
  EXPECT_NEAR(u.force_n, t.force_n,
              0.5 * newtons_per_bit * layout_->region_sensors(Region::Heel).size());
}

// The adaptive threshold is a share of the step's highest summed reading, which the mixing
// raised. Corrected, the readings take that share of their own highest sum, as the segmenter
// would have set it for the cells' own readings: the same cells count as without crosstalk,
// where the mixed readings' threshold drops the cap's lowest ones.
TEST_F(StanceTest, TheCorrectedReadingsTakeTheThresholdOfTheirOwnSummedReading) {
  const double coupling = 0.08;
  const std::vector<std::uint8_t> own = heel_cap(*layout_, 0.8, 20.0, 150.0);
  const std::vector<std::uint8_t> mixed = mixed_readings(*layout_, own, coupling);
  const auto summed = [](const std::vector<std::uint8_t>& bits) {
    double s = 0.0;
    for (std::uint8_t b : bits) s += b - 2.0;
    return s;
  };
  // The segmenter's threshold: a share of the step's highest zeroed summed bits; here the share
  // that puts the cells' own readings' threshold a bit under the lowest of 6 bits or more, clear
  // of what the mixed readings' rounding leaves on the corrected ones (0.52 bits on that cell).
  double lowest = 255.0;
  for (std::size_t c : layout_->region_sensors(Region::Heel)) {
    if (own[c] - 2.0 >= 6.0) lowest = std::min(lowest, own[c] - 2.0);
  }
  const double share = (lowest - 1.0) / summed(own);
  const auto with_threshold = [&](Step step, const std::vector<std::uint8_t>& bits) {
    step.max_summed_bits = summed(bits);
    step.adaptive_threshold_bits = share * step.max_summed_bits;
    return step;
  };
  const Step plain = with_threshold(make_step({own, own}), own);
  const Step step = with_threshold(make_step({mixed, mixed}), mixed);
  ASSERT_GT(step.adaptive_threshold_bits, 1.2 * plain.adaptive_threshold_bits);
  // Cells whose corrected reading lies between the two thresholds: what the mixed readings'
  // threshold would drop.
  std::vector<double> corrected(mixed.size());
  for (std::size_t c = 0; c < mixed.size(); ++c) corrected[c] = mixed[c] - 2.0;
  const CrosstalkCorrection correction(*layout_, coupling);
  correction.undo(corrected);
  int between = 0;
  for (std::size_t c : layout_->region_sensors(Region::Heel)) {
    between += corrected[c] >= plain.adaptive_threshold_bits &&
               corrected[c] < step.adaptive_threshold_bits;
  }
  ASSERT_GT(between, 0);
  const StanceSeries truth = measure_stance(plain, *layout_, config_.calibration);
  const StanceSeries undone = measure_stance(step, *layout_, config_.calibration, nullptr,
                                             CellMeanFootprint::Skip, &correction);
  const RegionSample& t = truth.at(1, Region::Heel);
  const RegionSample& u = undone.at(1, Region::Heel);
  std::printf("heel: %d cells own, %d corrected (%d between the thresholds %.2f and %.2f)\n",
              t.active_sensors, u.active_sensors, between, plain.adaptive_threshold_bits,
              step.adaptive_threshold_bits);
  EXPECT_EQ(u.active_sensors, t.active_sensors);
  ASSERT_TRUE(t.footprint_area_mm2 && u.footprint_area_mm2);
  EXPECT_NEAR(*u.footprint_area_mm2 / *t.footprint_area_mm2, 1.0, 0.01);
  // Where the threshold is the sensors' noise floor, it stays: the cells between go.
  Step floored = step;
  floored.threshold_floor_bits = step.adaptive_threshold_bits;
  const StanceSeries kept = measure_stance(floored, *layout_, config_.calibration, nullptr,
                                           CellMeanFootprint::Skip, &correction);
  EXPECT_EQ(kept.at(1, Region::Heel).active_sensors, u.active_sensors - between);
}

// A sensor that still reads after its load has gone (creep) reads a few bits more on every cell
// of the earlier, wider footprint: here 4 bits on the whole heel around a small cap of 8. Taken
// in, those readings flatten the cap and widen it by about three quarters. Two fits of the same
// contact that far apart say one of them is wrong, and which one the frame cannot tell (a
// thresholded fit on a few nearly flat loads extrapolates as far): the frame gets none.
TEST_F(StanceTest, FootprintsThatDisagreeLeaveTheFrameWithoutOne) {
  const double aspect = 0.8;
  const Step step = make_step(
      {heel_cap(*layout_, aspect, 30.0, 200.0), heel_cap(*layout_, aspect, 15.0, 8.0, 4.0)});
  const StanceSeries series = measure_stance(step, *layout_, config_.calibration);
  ASSERT_EQ(series.size(), 2u);
  const double shared = heel_shared_aspect(series);
  const CellSize cell{layout_->geometry().width_mm, layout_->geometry().height_mm};
  std::vector<CellCentre> unloaded;
  for (std::size_t i : layout_->region_sensors(Region::Heel)) {
    if (static_cast<double>(step.stance[1].bits[i]) - 2.0 < step.adaptive_threshold_bits) {
      unloaded.push_back({layout_->sensor(i).grid_x_mm, layout_->sensor(i).grid_y_mm});
    }
  }
  const auto above =
      footprint_area_at_aspect_mm2(heel_loads(step, *layout_, 1, true), cell, shared, unloaded);
  const auto all = footprint_area_unthresholded_mm2(heel_loads(step, *layout_, 1, false), cell,
                                                    shared, step.adaptive_threshold_bits);
  ASSERT_TRUE(above.has_value());
  ASSERT_TRUE(all.has_value());
  EXPECT_GT(*all / *above, 1.5);
  EXPECT_FALSE(series.at(1, Region::Heel).footprint_area_mm2.has_value());
  EXPECT_TRUE(series.at(0, Region::Heel).footprint_area_mm2.has_value());
}

// The simulator's two rasters are the two ways a cell can read: over a session's steps the
// evidence names the one each session was made with, by nearly every region-frame, and finds no
// crosstalk to undo. Sizes 35-36 and 45-46, whose cells are the smallest and the largest against
// the contacts.
TEST_F(StanceTest, TheCellsReadingIsTheOneTheSessionWasRasterisedWith) {
  const auto dir = test::scratch_dir("stance_cell_reading");
  for (const InsoleSize size : {InsoleSize::S35_36, InsoleSize::S45_46}) {
    const InsoleLayout layout(config_.insole(size), config_.sensor);
    for (const Rasterisation raster : {Rasterisation::CellCentre, Rasterisation::Coverage}) {
      SimulationOptions options;
      options.size = size;
      options.duration_s = 8.0;
      options.seed = 21;
      options.rasterisation = raster;
      const auto csv = dir / (std::string(insole_size_name(size)) + "-" +
                              std::string(rasterisation_name(raster)) + ".csv");
      simulate_session(config_, options, csv,
                       std::filesystem::path(csv).replace_extension(".json"));
      CellReadingEvidence evidence;
      segment_session(csv, config_, [&](Step&& step) {
        if (step.status == StepStatus::Ok) evidence += cell_reading_evidence(step, layout);
      });
      const bool mean = raster == Rasterisation::Coverage;
      const CellReadingFits& fits = evidence.fits();
      std::printf(
          "%s, %s raster: averaging cells fit %d of %d region-frames better; crosstalk %.3f\n",
          std::string(insole_size_name(size)).c_str(),
          std::string(rasterisation_name(raster)).c_str(), fits.mean_better, fits.frames,
          evidence.coupling());
      ASSERT_GE(fits.frames, 30);
      EXPECT_EQ(evidence.favoured(), mean ? CellReading::Mean : CellReading::Centre);
      const int wins = mean ? fits.mean_better : fits.frames - fits.mean_better;
      EXPECT_GE(wins, 0.9 * fits.frames);
      EXPECT_LT(evidence.coupling(), 0.03);
    }
  }
}

// Crosstalk spreads a cap's readings onto the cells around it, as cells that average the
// pressure do: as read, a coupling of 0.1 made cells that read at their centres look averaging
// (the matrix's session of seed 124 took footprint-mean, and its gap shrink fell from 48 to 28 %).
// Weighed with the crosstalk undone, each raster is named again, and the coupling the readings
// fit best at is the session's. Size 41-42.
TEST_F(StanceTest, CrosstalkIsUndoneBeforeTheCellsReadingIsJudged) {
  const auto dir = test::scratch_dir("stance_cell_reading_crosstalk");
  const InsoleLayout layout(config_.insole(InsoleSize::S41_42), config_.sensor);
  for (const Rasterisation raster : {Rasterisation::CellCentre, Rasterisation::Coverage}) {
    for (const double coupling : {0.05, 0.1}) {
      SimulationOptions options;
      options.size = InsoleSize::S41_42;
      options.duration_s = 8.0;
      options.seed = 124;
      options.rasterisation = raster;
      options.effects = {"crosstalk"};
      options.effect_params["crosstalk"] = {{"coupling", coupling}};
      const auto csv = dir / fmt::format("{}-{}.csv", rasterisation_name(raster), coupling);
      simulate_session(config_, options, csv,
                       std::filesystem::path(csv).replace_extension(".json"));
      std::vector<Step> steps;
      segment_session(csv, config_, [&](Step&& step) {
        if (step.status == StepStatus::Ok) steps.push_back(std::move(step));
      });
      const CellReadingEvidence evidence = cell_reading_evidence(steps, layout);
      const CellReadingFits& as_read = evidence.at_coupling[0];
      std::printf(
          "%s raster, coupling %.2f: as read averaging cells fit %d of %d region-frames better; "
          "with %.3f undone %d of %d\n",
          std::string(rasterisation_name(raster)).c_str(), coupling, as_read.mean_better,
          as_read.frames, evidence.coupling(), evidence.fits().mean_better, evidence.fits().frames);
      const bool mean = raster == Rasterisation::Coverage;
      EXPECT_EQ(evidence.favoured(), mean ? CellReading::Mean : CellReading::Centre);
      EXPECT_NEAR(evidence.coupling(), coupling, 0.012);
      if (!mean && coupling == 0.1) {
        EXPECT_NE(as_read.favoured(), CellReading::Centre);
      }
    }
  }
}

// The reading is favoured only by three quarters of ten frames or more, and only where its summed
// residual is the smaller too.
TEST(CellReadingEvidence, FavoursAReadingOnlyByThreeQuartersOfTenFrames) {
  CellReadingFits e;
  e.frames = 9;
  e.mean_better = 9;
  e.centre_residual_ss = 100.0;
  e.mean_residual_ss = 10.0;
  EXPECT_FALSE(e.favoured().has_value());
  e.frames = 12;
  EXPECT_EQ(e.favoured(), CellReading::Mean);
  e.mean_better = 8;  // two thirds
  EXPECT_FALSE(e.favoured().has_value());
  e.mean_better = 3;  // the centre's 9 of 12, but its summed residual is the larger
  EXPECT_FALSE(e.favoured().has_value());
  e.mean_residual_ss = 200.0;
  EXPECT_EQ(e.favoured(), CellReading::Centre);
  CellReadingEvidence sum;
  sum.at_coupling[3] = e;
  sum += sum;
  EXPECT_EQ(sum.at_coupling[3].frames, 24);
  EXPECT_EQ(sum.at_coupling[3].mean_better, 6);
  EXPECT_EQ(sum.at_coupling[3].mean_residual_ss, 400.0);
  EXPECT_EQ(sum.at_coupling[2].frames, 0);
}

// The coupling is where the better reading's residual per cell is least: on a residual that is
// a parabola in the coupling the vertex exactly, between the grid's points; at the grid's end
// where the least is there; 0 without frames, or where the least is not clearly below the
// residual as read. Couplings whose fits all failed say nothing.
TEST(CellReadingEvidence, CouplingIsTheVertexOfTheBestReadingsResidual) {
  const auto evidence = [](double vertex, double centre_offset, double floor = 0.5) {
    CellReadingEvidence e;
    for (std::size_t k = 0; k < CellReadingEvidence::kCouplings.size(); ++k) {
      const double d = CellReadingEvidence::kCouplings[k] - vertex;
      CellReadingFits& f = e.at_coupling[k];
      f.frames = 20;
      f.cells = 400;
      f.mean_residual_ss = 400.0 * (floor + 1000.0 * d * d);
      f.centre_residual_ss = 400.0 * (floor + centre_offset + 1000.0 * d * d);
    }
    return e;
  };
  EXPECT_NEAR(evidence(0.057, 1.0).coupling(), 0.057, 1e-12);
  EXPECT_EQ(evidence(0.057, 1.0).best_index(), 3u);
  EXPECT_EQ(evidence(0.057, 1.0).favoured(), std::nullopt);     // no frame said which fits better
  EXPECT_NEAR(evidence(0.057, -0.4).coupling(), 0.057, 1e-12);  // the centre's residual
  EXPECT_EQ(evidence(0.3, 1.0).coupling(), CellReadingEvidence::kCouplings.back());
  EXPECT_EQ(evidence(-0.01, 1.0).coupling(), 0.0);
  // Where the caps leave a misfit that the least as read is near, the coupling is not taken: on
  // a floor of 16 bits^2 the least's residual RMS is 0.91 of the one as read (over 5/6), on a
  // floor of 1 0.49.
  EXPECT_EQ(evidence(0.057, 1.0, 16.0).best_index(), 0u);
  EXPECT_EQ(evidence(0.057, 1.0, 16.0).coupling(), 0.0);
  EXPECT_EQ(evidence(0.057, 1.0, 1.0).best_index(), 3u);
  CellReadingEvidence failed = evidence(0.057, 1.0);
  failed.at_coupling[3] = {};
  EXPECT_NE(failed.best_index(), 3u);
  EXPECT_EQ(CellReadingEvidence{}.coupling(), 0.0);
}

// One hand-made heel cap read at the cells' centres: one region-frame, which the reading at the
// centres fits better, too few to favour either; a zero of the wrong size throws.
TEST_F(StanceTest, OneStepsHeelIsOneRegionFrameOfEvidence) {
  const auto bits = heel_cap(*layout_, 17.0 / 28.0, 28.0, 150.0);
  Step step = make_step({bits, bits});
  const CellReadingEvidence evidence = cell_reading_evidence(step, *layout_);
  EXPECT_EQ(evidence.coupling(), 0.0);
  const CellReadingFits& e = evidence.fits();
  EXPECT_EQ(e.frames, 1);
  EXPECT_EQ(e.mean_better, 0);
  EXPECT_EQ(e.cells, static_cast<int>(layout_->region_sensors(Region::Heel).size()));
  EXPECT_LT(e.centre_residual_ss, e.mean_residual_ss);
  EXPECT_FALSE(e.favoured().has_value());
  step.sensor_zero_bits.resize(3);
  EXPECT_THROW(cell_reading_evidence(step, *layout_), std::invalid_argument);
}

// A walk longer than kMaxSteps is weighed at that many steps spread evenly over it: of 400
// steps whose first half carries a heel cap and the second nothing, half the weighed steps give
// a region-frame (the first 200 alone would give 200); a shorter walk is weighed whole.
TEST_F(StanceTest, ALongWalkIsWeighedAtStepsSpreadOverIt) {
  const auto bits = heel_cap(*layout_, 17.0 / 28.0, 28.0, 150.0);
  const Step capped = make_step({bits, bits});
  const Step empty = make_step({std::vector<std::uint8_t>(layout_->sensor_count(), 0)});
  std::vector<Step> walk(2 * CellReadingEvidence::kMaxSteps, empty);
  std::fill_n(walk.begin(), CellReadingEvidence::kMaxSteps, capped);
  EXPECT_EQ(cell_reading_evidence(walk, *layout_).at_coupling[0].frames,
            static_cast<int>(CellReadingEvidence::kMaxSteps / 2));
  walk.resize(CellReadingEvidence::kMaxSteps / 2);
  EXPECT_EQ(cell_reading_evidence(walk, *layout_).at_coupling[0].frames,
            static_cast<int>(CellReadingEvidence::kMaxSteps / 2));
}

TEST_F(StanceTest, RejectsAZeroOfTheWrongSize) {
  Step step = make_step({std::vector<std::uint8_t>(layout_->sensor_count(), 0)});
  step.sensor_zero_bits.resize(3);
  EXPECT_THROW(measure_stance(step, *layout_, config_.calibration), std::invalid_argument);
}

}  // namespace
}  // namespace gaitmon
