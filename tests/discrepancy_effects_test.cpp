// The candidate effects keep the promises the workflow's solver relies on: one that says it is
// affine in the model force is, and one that says it only adds to the force does. The solver
// solves K and D in closed form for the first and computes the chain's linear part once for the
// second, so a false promise would give wrong fits without any error. The same goes for the
// slope an effect gives Gauss-Newton.
#include "src/discrepancy_effects.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "gaitmon/simulator.hpp"
#include "gaitmon/tissue_model.hpp"
#include "test_support.hpp"

namespace gaitmon::discrepancy_detail {
namespace {

using test::kPi;
constexpr std::size_t kFrames = 60;

// A stance of one region: a half-sine of area, depth and force, 10-ms frames.
Unit stance(Region region, int step, double t0_s) {
  Unit u;
  u.region = region;
  u.step = step;
  u.dt_s = 0.01;
  u.t_contact_s = t0_s;
  for (std::size_t i = 0; i < kFrames; ++i) {
    const double s = std::sin(kPi * (static_cast<double>(i) + 0.5) / kFrames);
    u.t.push_back(t0_s + 0.01 * static_cast<double>(i));
    u.area.push_back(1200.0 * s);
    u.d_mm.push_back(6.0 * s);
    u.y.push_back(400.0 * s * s);
  }
  u.peak_n = 400.0;
  u.shape_model.id = {3000.0, 0.0, 0.3, 0.0, 1.0};
  // As if measured again for crosstalk: the correction shrinks the area and takes a share of
  // the force off, both growing with the coupling.
  CrosstalkSeries x;
  for (double k : kCrosstalkGrid) {
    std::vector<double> area, removed;
    for (std::size_t i = 0; i < kFrames; ++i) {
      area.push_back(u.area[i] * (1.0 - 2.0 * k));
      removed.push_back(2.0 * k * u.y[i]);
    }
    x.area_mm2.push_back(area);
    x.removed_n.push_back(removed);
    std::vector<double> spill;
    for (double y : u.y) spill.push_back(0.5 * k * y);
    x.spill_in_n.push_back(spill);
  }
  u.crosstalk = std::make_shared<const CrosstalkSeries>(std::move(x));
  return u;
}

// Two forces unlike each other and unlike the measured one.
std::vector<double> force(double scale, double cycles) {
  std::vector<double> f;
  for (std::size_t i = 0; i < kFrames; ++i) {
    const double x = (static_cast<double>(i) + 0.5) / kFrames;
    f.push_back(scale * std::sin(kPi * x) * (1.2 + std::cos(2.0 * kPi * cycles * x)));
  }
  return f;
}

std::vector<double> apply(const Applied& e, std::size_t ui, const Unit& u,
                          const std::vector<double>& F, std::size_t choice) {
  std::vector<double> out(F.size());
  e.apply(ui, u, F, out, choice);
  return out;
}

std::vector<double> combine(double a, const std::vector<double>& x, double b,
                            const std::vector<double>& y) {
  std::vector<double> out(x.size());
  for (std::size_t i = 0; i < x.size(); ++i) out[i] = a * x[i] + b * y[i];
  return out;
}

// The largest |T(a F1 + b F2) - T(0) - a (T(F1) - T(0)) - b (T(F2) - T(0))| over the frames.
double affine_defect(const Applied& e, std::size_t ui, const Unit& u, std::size_t choice) {
  const std::vector<double> F1 = force(300.0, 1.0);
  const std::vector<double> F2 = force(150.0, 2.5);
  const std::vector<double> zero(kFrames, 0.0);
  const double a = 0.7;
  const double b = 1.9;
  const std::vector<double> T0 = apply(e, ui, u, zero, choice);
  const std::vector<double> T1 = apply(e, ui, u, F1, choice);
  const std::vector<double> T2 = apply(e, ui, u, F2, choice);
  const std::vector<double> T12 = apply(e, ui, u, combine(a, F1, b, F2), choice);
  double worst = 0.0;
  for (std::size_t i = 0; i < kFrames; ++i) {
    const double predicted = T0[i] + a * (T1[i] - T0[i]) + b * (T2[i] - T0[i]);
    worst = std::max(worst, std::abs(T12[i] - predicted));
  }
  return worst;
}

// The largest |(T(F) - F) - T(0)| over the frames, for two forces.
double additive_defect(const Applied& e, std::size_t ui, const Unit& u, std::size_t choice) {
  const std::vector<double> zero(kFrames, 0.0);
  const std::vector<double> T0 = apply(e, ui, u, zero, choice);
  double worst = 0.0;
  for (const std::vector<double>& F : {force(300.0, 1.0), force(150.0, 2.5)}) {
    const std::vector<double> T = apply(e, ui, u, F, choice);
    for (std::size_t i = 0; i < kFrames; ++i)
      worst = std::max(worst, std::abs(T[i] - F[i] - T0[i]));
  }
  return worst;
}

struct Made {
  std::string name;
  std::unique_ptr<Applied> effect;
};

// Every candidate at the middle of each of its parameters' grids, over a heel and a metatarsal
// stance whose force carries over from one to the next.
std::vector<Made> every_candidate(const std::vector<Unit>& units) {
  std::vector<Made> made;
  for (const CandidateSpec& spec : candidate_specs(112.5, 0.0441)) {
    std::vector<double> theta;
    for (const ParamSpec& p : spec.params) theta.push_back(p.grid[p.grid.size() / 2]);
    made.push_back({spec.name, spec.make(units, theta)});
  }
  return made;
}

std::vector<Unit> two_steps() {
  std::vector<Unit> units{stance(Region::Heel, 0, 0.5), stance(Region::Heel, 1, 1.6),
                          stance(Region::Met1_2, 0, 0.8)};
  units[1].prev = 0;
  return units;
}

TEST(DiscrepancyEffects, ThoseThatSayTheyAreAffineInTheForceAre) {
  const std::vector<Unit> units = two_steps();
  int checked = 0;
  for (const Made& m : every_candidate(units)) {
    if (!m.effect->affine()) continue;
    for (std::size_t ui = 0; ui < units.size(); ++ui) {
      if (!m.effect->affects(units[ui])) continue;
      for (std::size_t c = 0; c < m.effect->choices(units[ui]); ++c) {
        EXPECT_LT(affine_defect(*m.effect, ui, units[ui], c), 1e-9)
            << m.name << " unit " << ui << " choice " << c;
        ++checked;
      }
    }
  }
  // Relaxation, hysteresis, creep and crosstalk on 3 units, 1 choice each; impact on 2 heels x
  // 21 onsets.
  EXPECT_EQ(checked, 4 * 3 + 2 * 21);
}

TEST(DiscrepancyEffects, TheAffineCheckCatchesTheCeilingThatIsNot) {
  const std::vector<Unit> units = two_steps();
  int found = 0;
  for (const Made& m : every_candidate(units)) {
    if (m.name != "sensor_saturation") continue;
    ++found;
    EXPECT_FALSE(m.effect->affine());
    EXPECT_GT(affine_defect(*m.effect, 0, units[0], 0), 1.0);
  }
  EXPECT_EQ(found, 1) << "no sensor_saturation candidate to check";
}

TEST(DiscrepancyEffects, ThoseThatSayTheyOnlyAddToTheForceDo) {
  const std::vector<Unit> units = two_steps();
  std::vector<std::string> additive, force_untouched;
  for (const Made& m : every_candidate(units)) {
    bool depends_on_force = false;
    bool affects_any = false;
    for (std::size_t ui = 0; ui < units.size(); ++ui) {
      if (!m.effect->affects(units[ui])) continue;
      affects_any = true;
      for (std::size_t c = 0; c < m.effect->choices(units[ui]); ++c) {
        const double defect = additive_defect(*m.effect, ui, units[ui], c);
        if (m.effect->additive()) {
          EXPECT_LT(defect, 1e-9) << m.name << " unit " << ui << " choice " << c;
        } else {
          depends_on_force = depends_on_force || defect > 1e-9;
        }
      }
    }
    if (!affects_any) {
      force_untouched.push_back(m.name);
    } else if (m.effect->additive()) {
      additive.push_back(m.name);
    } else {
      // The check can tell: every other effect changes with the force it is given.
      EXPECT_TRUE(depends_on_force) << m.name;
    }
  }
  EXPECT_EQ(additive, std::vector<std::string>{"impact_transient"});
  // The drift reads in the zero windows only; the zeroing takes it off the stance.
  EXPECT_EQ(force_untouched, std::vector<std::string>{"thermal_drift"});
}

// Gauss-Newton takes an effect's slope in place of differences, so a slope that is off would
// steer the fits without an error. Each frame's slope is checked against differences of `apply`
// over that frame alone (forward or backward: the fraction is interpolated linearly in a table,
// so a central difference may straddle a knot), and no other frame may move with it.
TEST(DiscrepancyEffects, ThoseThatGiveTheirSlopeGiveApplysSlopeFrameByFrame) {
  const std::vector<Unit> units = two_steps();
  std::vector<std::string> with_slope;
  for (const Made& m : every_candidate(units)) {
    const Unit& u = units[0];
    const std::vector<double> F = force(300.0, 1.0);
    std::vector<double> out(kFrames), slope(kFrames);
    if (!m.effect->apply_with_slope(0, u, F, out, slope)) continue;
    with_slope.push_back(m.name);
    const std::vector<double> plain = apply(*m.effect, 0, u, F, 0);
    int moved = 0;
    for (std::size_t i = 0; i < kFrames; ++i) {
      EXPECT_DOUBLE_EQ(out[i], plain[i]) << m.name << " frame " << i;
      const double h = 1e-6 * F[i];
      std::vector<double> up = F, down = F;
      up[i] += h;
      down[i] -= h;
      const std::vector<double> at_up = apply(*m.effect, 0, u, up, 0);
      const std::vector<double> at_down = apply(*m.effect, 0, u, down, 0);
      const double forward = (at_up[i] - plain[i]) / h;
      const double backward = (plain[i] - at_down[i]) / h;
      const double off = std::min(std::abs(slope[i] - forward), std::abs(slope[i] - backward));
      EXPECT_LT(off, 1e-6 * std::max(1.0, std::abs(slope[i])))
          << m.name << " frame " << i << ": slope " << slope[i] << ", differences " << forward
          << " and " << backward;
      for (std::size_t j = 0; j < kFrames; ++j) {
        if (j != i) {
          EXPECT_EQ(at_up[j], plain[j]) << m.name << " frame " << j << " moved with " << i;
        }
      }
      if (std::abs(slope[i] - 1.0) > 0.01) ++moved;
    }
    // The ceiling is below every frame's peak here, so the slope is not the identity's.
    EXPECT_EQ(moved, static_cast<int>(kFrames)) << m.name;
  }
  EXPECT_EQ(with_slope, std::vector<std::string>{"sensor_saturation"});
}

// ---- The candidates against the simulator's effects and their closed forms ----

constexpr double kFrameS = 0.01;
constexpr double kStanceS = 0.6;
using test::kHeel;

double frame_time(int k) {
  return static_cast<double>(k) / 100.0;
}

// One foot's heel over `contacts` stances 1.1 s apart that start between frames: the frames in
// contact, with the model's exact force over a half-sine of deformation. The zero windows are
// read 20 frames before the first and after the last frame of each stance.
std::vector<Unit> heel_contacts(int contacts) {
  std::vector<Unit> units;
  for (int c = 0; c < contacts; ++c) {
    const double start = 0.503 + 1.1 * c;
    Unit u;
    u.step = c;
    u.dt_s = kFrameS;
    u.t_contact_s = start;
    u.prev = c - 1;
    u.chain = 0;
    int first = -1;
    int last = -1;
    for (int k = 0; k < 400 * contacts; ++k) {
      const double x = (frame_time(k) - start) / kStanceS;
      if (!(x > 0.0 && x < 1.0)) continue;
      if (first < 0) first = k;
      last = k;
      const double d = 6.0 * std::sin(kPi * x);
      const double ddot = 6.0 * kPi / kStanceS * std::cos(kPi * x);
      u.t.push_back(frame_time(k));
      u.d_mm.push_back(d);
      u.area.push_back(contact_area_mm2(kHeel, d));
      u.y.push_back(force_n(kHeel, d, ddot, ModelVariant::Correct));
    }
    u.t_pre_zero_s = frame_time(first - 20);
    u.t_post_zero_s = frame_time(last + 20);
    u.peak_n = *std::max_element(u.y.begin(), u.y.end());
    units.push_back(u);
  }
  return units;
}

std::unique_ptr<Applied> candidate(const std::string& name, const std::vector<Unit>& units,
                                   const std::vector<double>& theta, double cell_area_mm2 = 112.5,
                                   double newtons_per_bit = 0.2824) {
  for (const CandidateSpec& spec : candidate_specs(cell_area_mm2, newtons_per_bit)) {
    if (spec.name == name) return spec.make(units, theta);
  }
  ADD_FAILURE() << "no candidate " << name;
  return nullptr;
}

struct Agreement {
  double force = 0.0;   ///< the largest |candidate - simulator| over the contact frames / peak
  double swing = 0.0;   ///< the same for the reading in the zero windows, summed over a unit's two
  double effect = 0.0;  ///< the largest |simulator - model| over the contact frames / peak
};

// The candidate is applied to the exact model force (each unit's y). The simulator's tissue
// effect sees the contact frames only, as simulate_session calls it, and its sensor effect every
// frame of three cells that share the region's force (in bits; swing frames read 0).
Agreement against_simulator(const std::string& name, const EffectParams& params,
                            const std::vector<double>& theta, bool sensor) {
  const std::vector<Unit> units = heel_contacts(2);
  const auto effect = make_simulation_effect(name, params);
  const auto applied = candidate(name, units, theta);
  const double newtons_per_bit = 0.2824;
  const std::array<double, 3> share{0.5, 0.3, 0.2};
  std::vector<double> window_sum(units.size(), 0.0);
  Agreement worst;
  std::size_t ui = 0;
  std::size_t i = 0;
  for (int k = 0; k < 400 * static_cast<int>(units.size()); ++k) {
    const double t = frame_time(k);
    const bool in_contact = ui < units.size() && i < units[ui].t.size() && units[ui].t[i] == t;
    const double model = in_contact ? units[ui].y[i] : 0.0;
    double simulated = model;
    if (sensor) {
      simulated = 0.0;
      for (std::size_t cell = 0; cell < share.size(); ++cell) {
        simulated += newtons_per_bit * effect->sensor_bits({Foot::Left, cell, t},
                                                           share[cell] * model / newtons_per_bit);
      }
      for (std::size_t w = 0; w < units.size(); ++w) {
        if (t == units[w].t_pre_zero_s || t == units[w].t_post_zero_s) window_sum[w] += simulated;
      }
    } else if (in_contact) {
      TissueSample sample;
      sample.t_s = t;
      sample.t_contact_start_s = units[ui].t_contact_s;
      sample.d_mm = units[ui].d_mm[i];
      sample.area_mm2 = units[ui].area[i];
      sample.frame_interval_s = units[ui].dt_s;
      simulated = effect->tissue_force_n(sample, model);
    }
    if (!in_contact) continue;
    const Unit& u = units[ui];
    std::vector<double> out(u.y.size());
    applied->apply(ui, u, u.y, out, 0);
    worst.force = std::max(worst.force, std::abs(out[i] - simulated) / u.peak_n);
    worst.effect = std::max(worst.effect, std::abs(simulated - model) / u.peak_n);
    if (++i == u.t.size()) {
      ++ui;
      i = 0;
    }
  }
  for (std::size_t w = 0; w < units.size(); ++w) {
    // swing_reading is the mean over the two windows.
    worst.swing = std::max(
        worst.swing, std::abs(2.0 * applied->swing_reading(w) - window_sum[w]) / units[w].peak_n);
  }
  return worst;
}

// Hysteresis, creep, relaxation and the impact are meant to be the simulator's effects in the
// workflow's terms (README, "The simulator's effects"): at the simulator's parameters, applied
// to the exact model force, each candidate reproduces the simulated force, on the foot's first
// contact and on the next one, whose state comes through the swing. The reference is the
// simulator's own effect (src/simulation_effects.cpp), driven frame by frame as the simulator
// drives it.
TEST(DiscrepancyEffects, CandidatesReproduceTheSimulatorsEffectsAtItsParameters) {
  const Agreement hysteresis = against_simulator(
      "hysteresis", {{"strength", 0.12}, {"transition_mm", 0.3}}, {0.12, 0.3}, false);
  const Agreement relaxation = against_simulator(
      "stress_relaxation", {{"strength", 0.3}, {"tau_s", 0.15}}, {0.3, 0.15}, false);
  const Agreement impact = against_simulator(
      "impact_transient", {{"amplitude_n", 80.0}, {"duration_s", 0.04}}, {80.0, 0.04}, false);
  const Agreement creep =
      against_simulator("sensor_creep", {{"gain", 0.15}, {"tau_s", 1.5}}, {0.15, 1.5}, true);
  std::printf(
      "candidate - simulator, share of the peak: hysteresis %.2e relaxation %.2e impact %.2e "
      "creep %.2e, creep in the zero windows %.2e\n",
      hysteresis.force, relaxation.force, impact.force, creep.force, creep.swing);
  // Each effect changes the force by far more than the agreement asserted.
  for (const Agreement* a : {&hysteresis, &relaxation, &impact, &creep}) EXPECT_GT(a->effect, 0.01);
  EXPECT_LT(hysteresis.force, 1e-11);
  EXPECT_LT(relaxation.force, 1e-12);
  EXPECT_LT(impact.force, 1e-12);
  EXPECT_LT(creep.force, 1e-12);
  EXPECT_LT(creep.swing, 1e-12);
}

// A warming insole: each region's zero moves by its cells times the drift between the mean times
// of the two steps' zero windows, and the stance force is left to the baseline (the zeroing at
// the windows on both sides takes a linear drift off it). Against the simulator's warm-up at a
// time constant far beyond these 3 s, where it is linear, in the same units: bits per cell, N.
TEST(DiscrepancyEffects, ThermalDriftMovesEachZeroByItsCellsTimesTheDrift) {
  std::vector<Unit> units = heel_contacts(3);
  for (Unit& u : units) u.cells = 3;
  const double npb = 0.2824;
  const double rate_bits_per_min = 20.0 * 60.0 / 1800.0;
  const auto applied = candidate("thermal_drift", units, {rate_bits_per_min}, 112.5, npb);
  const auto effect =
      make_simulation_effect("thermal_drift", {{"offset_bits", 20.0}, {"tau_s", 1800.0}});
  const auto simulated_zero = [&](const Unit& u) {
    double bits = 0.0;
    for (std::size_t cell = 0; cell < 3; ++cell) {
      bits += effect->sensor_bits({Foot::Left, cell, u.t_pre_zero_s}, 0.0) +
              effect->sensor_bits({Foot::Left, cell, u.t_post_zero_s}, 0.0);
    }
    return 0.5 * bits * npb;
  };
  for (std::size_t ui = 1; ui < units.size(); ++ui) {
    const Unit& u = units[ui];
    const Unit& p = units[ui - 1];
    EXPECT_FALSE(applied->affects(u));
    const double dt = 0.5 * (u.t_pre_zero_s + u.t_post_zero_s - p.t_pre_zero_s - p.t_post_zero_s);
    const double change = applied->swing_reading(ui) - applied->swing_reading(ui - 1);
    EXPECT_NEAR(change, 3.0 * npb * rate_bits_per_min / 60.0 * dt, 1e-12);
    const double sim_change = simulated_zero(u) - simulated_zero(p);
    EXPECT_GT(sim_change, 0.0);
    EXPECT_NEAR(change / sim_change, 1.0, 3e-3) << ui;
    std::vector<double> out(u.y.size());
    applied->apply(ui, u, u.y, out, 0);
    EXPECT_EQ(out, u.y);
  }
  // A unit without both windows has no zero the drift could be read from.
  units[1].t_post_zero_s = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(candidate("thermal_drift", units, {rate_bits_per_min}, 112.5, npb)->swing_reading(1),
            0.0);
}

// The units of two_steps were measured again with areas (1 - 2 k), takings 2 k y and spills from
// other regions 0.5 k y, linear in the coupling k, so interpolation between the couplings
// measured (and the unit's own area at k = 0 below the first) gives them exactly at any k, and
// so the force's gain and spill.
TEST(DiscrepancyEffects, CrosstalkDrivesTheModelByTheCorrectedAreaAtItsCoupling) {
  const std::vector<Unit> units = two_steps();
  for (const double k : {0.005, 0.0425, 0.2}) {
    SCOPED_TRACE(k);
    const auto applied = candidate("crosstalk", units, {k}, 112.5, 0.2824);
    for (std::size_t ui = 0; ui < units.size(); ++ui) {
      const Unit& u = units[ui];
      ASSERT_TRUE(applied->affects(u));
      std::vector<double> area(u.area.size());
      for (std::size_t i = 0; i < area.size(); ++i) area[i] = u.area[i] * (1.0 - 2.0 * k);
      const Shapes expected = shapes_of(u.t, area, u.shape_model);
      const Unit* got = applied->seen(ui);
      ASSERT_NE(got, nullptr);
      ASSERT_EQ(got->En.size(), expected.En.size());
      // The chain's other effects see the corrected contact: its area, and the deformation and
      // rate from it.
      for (std::size_t i = 0; i < area.size(); ++i) {
        EXPECT_NEAR(got->area[i], area[i], 1e-9 * area[i]);
        EXPECT_NEAR(got->d_mm[i], expected.d_mm[i], 1e-12 + 1e-9 * expected.d_mm[i]);
        EXPECT_NEAR(got->ddot_mm_per_s[i], expected.ddot_mm_per_s[i],
                    1e-9 * (1.0 + std::abs(expected.ddot_mm_per_s[i])));
      }
      EXPECT_EQ(got->E, got->En.front());
      EXPECT_EQ(got->y, u.y);
      for (std::size_t n = 0; n < expected.En.size(); ++n) {
        for (std::size_t i = 0; i < area.size(); ++i) {
          EXPECT_NEAR(got->En[n][i], expected.En[n][i], 1e-9 * (1.0 + expected.En[n][i]));
        }
      }
      for (std::size_t i = 0; i < area.size(); ++i) {
        EXPECT_NEAR(got->V[i], expected.V[i], 1e-9 * (1.0 + std::abs(expected.V[i])));
      }
      // A smaller area, a smaller model force at the same stiffness.
      EXPECT_LT(got->En[0][kFrames / 2], shapes_of(u.t, u.area, u.shape_model).En[0][kFrames / 2]);
      const std::vector<double> F = force(300.0, 1.0);
      std::vector<double> out(F.size());
      applied->apply(ui, u, F, out, 0);
      // The corrected force is (1 - 2 k) y and the spill from other regions 0.5 k y, so the
      // region's own mixing is a gain of (1 - 0.5 k) / (1 - 2 k) on the model (under 1 + 4 k),
      // the spill added.
      for (std::size_t i = 0; i < F.size(); ++i) {
        const double expected = F[i] * (1.0 - 0.5 * k) / (1.0 - 2.0 * k) + 0.5 * k * u.y[i];
        EXPECT_NEAR(out[i], expected, 1e-9 * (1.0 + std::abs(expected)));
      }
    }
  }
  // No coupling, no correction; and a unit that was not measured again is left alone.
  EXPECT_FALSE(candidate("crosstalk", units, {0.0}, 112.5, 0.2824)->affects(units[0]));
  std::vector<Unit> unmeasured = two_steps();
  unmeasured[0].crosstalk.reset();
  const auto applied = candidate("crosstalk", unmeasured, {0.05}, 112.5, 0.2824);
  EXPECT_FALSE(applied->affects(unmeasured[0]));
  EXPECT_EQ(applied->seen(0), nullptr);
  EXPECT_TRUE(applied->affects(unmeasured[1]));
}

// Closed forms on simple inputs, whatever the simulator does. Hysteresis on a triangle of
// deformation (0.1 mm steps up to 3 mm and back) under a constant 100 N, from the unloaded state
// z = -1: dz/dd = (sign(dd) - z) / d_s gives z = 1 - 2 exp(-d / d_s) while loading and
// z = -1 + (1 + z(3)) exp(-(3 - d) / d_s) while unloading. Creep and relaxation under a
// constant 200 N held from the frame before the first: the continuous first-order lag of that
// step, 1 - exp(-(t - t0 + dt) / tau), times +gain or -strength.
TEST(DiscrepancyEffects, HysteresisCreepAndRelaxationFollowTheirClosedForms) {
  Unit triangle;
  std::vector<double> expected;
  const double h = 0.12;
  const double ds = 0.3;
  const double z_top = 1.0 - 2.0 * std::exp(-3.0 / ds);
  for (int i = 1; i <= 59; ++i) {
    const double d = 0.1 * (i <= 30 ? i : 60 - i);
    const double z =
        i <= 30 ? 1.0 - 2.0 * std::exp(-d / ds) : -1.0 + (1.0 + z_top) * std::exp(-(3.0 - d) / ds);
    triangle.t.push_back(kFrameS * i);
    triangle.d_mm.push_back(d);
    expected.push_back(100.0 * (1.0 + h * z));
  }
  const std::vector<Unit> one{triangle};
  const std::vector<double> hysteresis = apply(*candidate("hysteresis", one, {h, ds}), 0, triangle,
                                               std::vector<double>(expected.size(), 100.0), 0);
  for (std::size_t i = 0; i < expected.size(); ++i) EXPECT_NEAR(hysteresis[i], expected[i], 1e-10);

  Unit held;
  held.dt_s = kFrameS;
  for (int i = 0; i < 300; ++i) {
    held.t.push_back(2.0 + kFrameS * i);
    held.y.push_back(200.0);
  }
  const std::vector<Unit> alone{held};
  const std::vector<double> creep =
      apply(*candidate("sensor_creep", alone, {0.15, 1.5}), 0, held, held.y, 0);
  const std::vector<double> relaxed =
      apply(*candidate("stress_relaxation", alone, {0.3, 0.15}), 0, held, held.y, 0);
  for (std::size_t i = 0; i < held.t.size(); ++i) {
    const double since = held.t[i] - held.t.front() + kFrameS;
    EXPECT_NEAR(creep[i], 200.0 * (1.0 + 0.15 * (1.0 - std::exp(-since / 1.5))), 1e-9);
    EXPECT_NEAR(relaxed[i], 200.0 * (1.0 - 0.3 * (1.0 - std::exp(-since / 0.15))), 1e-9);
  }
  EXPECT_NEAR(relaxed.back(), 140.0, 1e-6);  // a held load relaxes to (1 - strength)
}

// Where the cells counted differ between the readings and their correction, the gain taken from
// them can exceed what mixing gives (1 + 4 k), or nothing corrected is left (the frame then takes
// its neighbour's gain). The prediction is still the measured force wherever the model is the
// corrected force, and the gain on the model stays within [0, 1 + 4 k].
TEST(DiscrepancyEffects, CrosstalkPredictsTheMeasuredForceWhereTheModelIsTheCorrectedForce) {
  std::vector<Unit> units = two_steps();
  Unit& u = units[0];
  const std::size_t spiking = kFrames / 3;  // corrected 0.1 y, spill 0.05 y: a gain of 9.5
  const std::size_t empty = kFrames / 2;    // nothing left after the correction
  CrosstalkSeries x = *u.crosstalk;
  for (std::size_t g = 0; g < kCrosstalkGrid.size(); ++g) {
    x.removed_n[g][spiking] = 0.9 * u.y[spiking];
    x.spill_in_n[g][spiking] = 0.05 * u.y[spiking];
    x.removed_n[g][empty] = u.y[empty];
  }
  u.crosstalk = std::make_shared<const CrosstalkSeries>(std::move(x));
  const double k = 0.05;
  const auto applied = candidate("crosstalk", units, {k}, 112.5, 0.2824);
  std::vector<double> corrected(kFrames), slope_probe(kFrames), at(kFrames), above(kFrames);
  for (std::size_t i = 0; i < kFrames; ++i) {
    corrected[i] = u.y[i] - u.crosstalk->removed_n[3][i];  // kCrosstalkGrid[3] is 0.05
    slope_probe[i] = corrected[i] + 10.0;
  }
  ASSERT_EQ(kCrosstalkGrid[3], k);
  applied->apply(0, u, corrected, at, 0);
  applied->apply(0, u, slope_probe, above, 0);
  for (std::size_t i = 0; i < kFrames; ++i) {
    EXPECT_NEAR(at[i], u.y[i], 1e-9 * u.y[i] + 1e-12) << i;
    const double gain = (above[i] - at[i]) / 10.0;
    EXPECT_GE(gain, 0.0) << i;
    EXPECT_LE(gain, 1.0 + 4.0 * k + 1e-12) << i;
  }
  EXPECT_NEAR((above[spiking] - at[spiking]) / 10.0, 1.0 + 4.0 * k, 1e-9);
  // Nothing corrected left: the gain of the frame after, (1 - 0.5 k) / (1 - 2 k) there.
  EXPECT_NEAR((above[empty] - at[empty]) / 10.0, (1.0 - 0.5 * k) / (1.0 - 2.0 * k), 1e-9);
}

// The ceiling's candidate against the capped raster it stands for. A paraboloid pressure
// p0 (1 - rho^2) over a heel-sized ellipse (30 x 45 mm) is read by cells of a fifth of the
// insole's size (1.5 x 3 mm, 255 counts = 64 N/cm^2) capped at 255 counts. Reference: the
// integral of the capped field, F0 (1 - L^2) with L = 1 - 255 / p0 (the capped share of the
// squared radius), which the raster's sum must follow to within its midpoint rule's error.
// The candidate sees the model force at the footprint the capped cells give, phi(L) times the
// contact's area (README, "Saturation and the footprint"), where a shallow contact's force is
// F0 phi^(2 + n) (n = 0.3, the candidate's), and must return the capped force.
TEST(DiscrepancyEffects, SaturationMatchesTheCappedIntegralOfAParaboloid) {
  const double a = 30.0;
  const double b = 45.0;
  const double w = 1.5;
  const double hgt = 3.0;
  const double cell_area = w * hgt;
  const double n_per_count = 0.64 / 255.0 * cell_area;  // 64 N/cm^2 = 0.64 N/mm^2
  const double contact_area = kPi * a * b;
  double worst_raster = 0.0;
  double worst_candidate = 0.0;
  for (double p0 : {300.0, 400.0, 600.0, 1000.0}) {
    const double F0 = p0 * n_per_count / cell_area * contact_area / 2.0;
    const double L = 1.0 - 255.0 / p0;
    const double capped = F0 * (1.0 - L * L);
    double raster = 0.0;
    for (int j = -20; j <= 20; ++j) {
      for (int i = -25; i <= 25; ++i) {
        const double x = (i + 0.25) * w;
        const double y = (j + 0.4) * hgt;
        const double rho2 = x * x / (a * a) + y * y / (b * b);
        if (rho2 < 1.0) raster += std::min(p0 * (1.0 - rho2), 255.0) * n_per_count;
      }
    }
    const double phi = (1.0 + L + L * L) / (1.0 + L);
    Unit u;
    u.area = {phi * contact_area};
    u.t = {0.0};
    const std::vector<Unit> units{u};
    const auto ceiling = candidate("sensor_saturation", units, {255.0}, cell_area, n_per_count);
    const double read = apply(*ceiling, 0, u, {F0 * std::pow(phi, 2.3)}, 0)[0];
    std::printf("p0 %4.0f counts: capped / uncapped force %.4f, raster %.4f, candidate %.4f\n", p0,
                capped / F0, raster / F0, read / F0);
    worst_raster = std::max(worst_raster, std::abs(raster - capped) / F0);
    worst_candidate = std::max(worst_candidate, std::abs(read - capped) / F0);
  }
  EXPECT_LT(worst_raster, 5e-3);
  EXPECT_LT(worst_candidate, 1e-4);
}

}  // namespace
}  // namespace gaitmon::discrepancy_detail
