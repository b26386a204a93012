// The discrepancy workflow's residual diagnostics on residuals made by hand, against values worked
// out on paper: the region x phase map, the runs test and the correlations with the model's state.
#include "src/discrepancy_diagnostics.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <string>
#include <vector>

namespace gaitmon::discrepancy_detail {
namespace {

// A unit whose residuals are `residuals`, over a constant prediction of 50 N.
Unit unit_with(Region region, const std::vector<double>& residuals,
               const std::vector<double>& phase, std::vector<double>* pred) {
  Unit u;
  u.region = region;
  u.peak_n = 100.0;
  pred->assign(residuals.size(), 50.0);
  for (std::size_t i = 0; i < residuals.size(); ++i) {
    u.y.push_back(50.0 + residuals[i]);
    u.t.push_back(0.01 * static_cast<double>(i));
  }
  u.phase = phase;
  u.floor2.assign(residuals.size(), 0.0);
  u.d_mm.assign(residuals.size(), 0.0);
  u.ddot_mm_per_s.assign(residuals.size(), 0.0);
  u.sat.assign(residuals.size(), 0.0);
  return u;
}

std::vector<double> evenly(std::size_t n) {
  std::vector<double> phase;
  for (std::size_t i = 0; i < n; ++i) phase.push_back(static_cast<double>(i) / n);
  return phase;
}

TEST(DiscrepancyDiagnostics, ResidualMapHasEveryRegionAndPhaseCell) {
  std::vector<std::vector<double>> preds(2);
  std::vector<Unit> units;
  units.push_back(unit_with(Region::Heel, {1, -1, 0, 3}, {0.0, 0.25, 0.5, 0.75}, &preds[0]));
  units[0].floor2 = {1, 1, 4, 4};
  // Phase 1 (the stance's last frame) falls in the last bin.
  units.push_back(unit_with(Region::Met1_2, {-2}, {1.0}, &preds[1]));
  units[1].floor2 = {0.25};

  const ResidualMap map = residual_map(units, preds, 2);
  ASSERT_EQ(map.bins, 2);
  ASSERT_EQ(map.cells.size(), 2 * kRegionCount);
  for (const ResidualCell& cell : map.cells) {
    const std::size_t at = index_of(cell.region) * 2 + static_cast<std::size_t>(cell.bin);
    EXPECT_EQ(&cell, &map.cells[at]) << "region-major order";
    if (cell.region == Region::Heel && cell.bin == 0) {
      EXPECT_EQ(cell.samples, 2);
      EXPECT_DOUBLE_EQ(cell.rms_n, 1.0);
      EXPECT_DOUBLE_EQ(cell.bias_n, 0.0);
      EXPECT_DOUBLE_EQ(cell.noise_floor_n, 1.0);
    } else if (cell.region == Region::Heel && cell.bin == 1) {
      EXPECT_EQ(cell.samples, 2);
      EXPECT_DOUBLE_EQ(cell.rms_n, std::sqrt(4.5));
      EXPECT_DOUBLE_EQ(cell.bias_n, 1.5);
      EXPECT_DOUBLE_EQ(cell.noise_floor_n, 2.0);
    } else if (cell.region == Region::Met1_2 && cell.bin == 1) {
      EXPECT_EQ(cell.samples, 1);
      EXPECT_DOUBLE_EQ(cell.rms_n, 2.0);
      EXPECT_DOUBLE_EQ(cell.bias_n, -2.0);
      EXPECT_DOUBLE_EQ(cell.noise_floor_n, 0.5);
    } else {
      EXPECT_EQ(cell.samples, 0);
      EXPECT_EQ(cell.rms_n, 0.0);
    }
  }
}

// Wald-Wolfowitz with n+ = n- = 5: 6 runs expected, variance 2 * 25 * 40 / (100 * 9) = 20 / 9.
constexpr double kRunsZ = 4.0 / 1.4907119849998598;  // (10 - 6) / sqrt(20 / 9)

TEST(DiscrepancyDiagnostics, RunsTestTellsAlternatingFromBlockedSigns) {
  const std::vector<double> alternating{1, -1, 1, -1, 1, -1, 1, -1, 1, -1};
  const std::vector<double> blocked{1, 1, 1, 1, 1, -1, -1, -1, -1, -1};
  std::vector<std::vector<double>> preds(1);
  std::vector<Unit> units{unit_with(Region::Heel, alternating, evenly(10), &preds[0])};
  EXPECT_NEAR(diagnose(units, preds, 10).runs_z, kRunsZ, 1e-12);

  units = {unit_with(Region::Heel, blocked, evenly(10), &preds[0])};
  EXPECT_NEAR(diagnose(units, preds, 10).runs_z, -kRunsZ, 1e-12);

  // Pooled: 12 runs against 12 expected. The alternating unit ends on a minus and the blocked one
  // starts on a plus; runs are counted within units, so that is no extra run.
  preds.resize(2);
  units = {unit_with(Region::Heel, alternating, evenly(10), &preds[0]),
           unit_with(Region::Heel, blocked, evenly(10), &preds[1])};
  EXPECT_NEAR(diagnose(units, preds, 10).runs_z, 0.0, 1e-12);
}

TEST(DiscrepancyDiagnostics, BiasPerPhaseAndCorrelationsWithTheModelState) {
  // Residual 2 i N on a peak of 100 N: 2 i % in phase bin i; it rises with d and t and falls with
  // the rate; the saturated-cell count and the step index are constant, so no correlation.
  std::vector<double> residuals;
  for (int i = 0; i < 10; ++i) residuals.push_back(2.0 * i);
  std::vector<std::vector<double>> preds(1);
  std::vector<Unit> units{unit_with(Region::Heel, residuals, evenly(10), &preds[0])};
  for (int i = 0; i < 10; ++i) {
    units[0].d_mm[i] = 3.0 + 0.5 * i;
    units[0].ddot_mm_per_s[i] = 7.0 - i;
    units[0].sat[i] = 2.0;
  }
  units[0].ordinal = 4;

  const ResidualDiagnostics d = diagnose(units, preds, 10);
  ASSERT_EQ(d.bias_per_phase_pct.size(), 10u);
  for (int i = 0; i < 10; ++i) EXPECT_NEAR(d.bias_per_phase_pct[i], 2.0 * i, 1e-12) << i;

  std::vector<std::string> names;
  for (const StateCorrelation& c : d.correlations) names.push_back(c.state);
  EXPECT_EQ(names, (std::vector<std::string>{"d_mm", "ddot_mm_per_s", "sign_ddot",
                                             "time_since_heel_strike_s", "load_history_impulse",
                                             "saturated_cells", "step_index"}));
  EXPECT_NEAR(d.correlations[0].r, 1.0, 1e-12);
  EXPECT_NEAR(d.correlations[1].r, -1.0, 1e-12);
  EXPECT_LT(d.correlations[2].r, -0.5);  // the rate turns negative after frame 7
  EXPECT_NEAR(d.correlations[3].r, 1.0, 1e-12);
  EXPECT_GT(d.correlations[4].r, 0.9);  // the impulse grows with every frame
  EXPECT_EQ(d.correlations[5].r, 0.0);
  EXPECT_EQ(d.correlations[6].r, 0.0);
}

// A stance-like force course, 400 sin^2 over `frames`, plus noise drawn by `draw`.
template <class Draw>
std::vector<double> stance_with_noise(std::size_t frames, Draw&& draw) {
  std::vector<double> y;
  for (std::size_t i = 0; i < frames; ++i) {
    const double s = std::sin(std::numbers::pi * (static_cast<double>(i) + 0.5) / frames);
    y.push_back(400.0 * s * s + draw());
  }
  return y;
}

// The noise floor's measurement part is the SD of the force's white noise, read from the
// scatter about a 5-point quadratic smoother. Reference: the noise put in. Gaussian noise of SD
// 2 N on one long course (20000 frames: the MAD's sampling error is about 1 %) and, averaged over
// 300 stances of 60 frames as the workflow sees them, within 3 % (with the upper of the two
// middle values taken as the median of an even count, the stances read 3.6 % high); a course
// without noise reads (almost) none.
TEST(DiscrepancyDiagnostics, NoiseSdRecoversGaussianNoise) {
  std::mt19937 rng(5);
  std::normal_distribution<double> gauss(0.0, 2.0);
  const double long_course = savgol_noise_sd(stance_with_noise(20000, [&] { return gauss(rng); }));
  double sum = 0.0;
  for (int k = 0; k < 300; ++k)
    sum += savgol_noise_sd(stance_with_noise(60, [&] { return gauss(rng); }));
  const double stances = sum / 300.0;
  std::printf("noise SD 2 N: read %.4f N on 20000 frames, %.4f N averaged over 60-frame stances\n",
              long_course, stances);
  EXPECT_NEAR(long_course, 2.0, 0.06);
  EXPECT_NEAR(stances, 2.0, 0.06);
  EXPECT_LT(savgol_noise_sd(stance_with_noise(60, [] { return 0.0; })), 0.05);
  EXPECT_EQ(savgol_noise_sd(std::vector<double>(6, 1.0)), 0.0);
}

// Uniform quantisation of step q (one bit, 0.2824 N on one sensor) is white noise of RMS
// q / sqrt 12. The MAD's factor 1.4826 is exact for Gaussian noise only: the smoother's residual
// of uniform noise has lighter tails, and the estimate reads 5.5 % high (Monte Carlo over 4e5
// samples of the residual's weights 18, -12, -12, 3, 3 / 35; 6.5 % here, on 20000 frames).
// Stated tolerance: 8 %.
TEST(DiscrepancyDiagnostics, NoiseSdRecoversUniformQuantisationNoise) {
  const double q = 0.2824;
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> uniform(-0.5 * q, 0.5 * q);
  const double read = savgol_noise_sd(stance_with_noise(20000, [&] { return uniform(rng); }));
  const double rms = q / std::sqrt(12.0);
  std::printf("quantisation step %.4f N: RMS %.5f N, read %.5f N (x %.4f)\n", q, rms, read,
              read / rms);
  EXPECT_NEAR(read, rms, 0.08 * rms);
}

}  // namespace
}  // namespace gaitmon::discrepancy_detail
