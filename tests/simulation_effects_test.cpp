// Tests of the simulator's physical effects: each changes the force or reading in the expected
// direction by an amount computed here from its definition, bad names or parameters fail, and a
// session with strong sensor creep still segments into its strides.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include "gaitmon/batch.hpp"
#include "gaitmon/config.hpp"
#include "gaitmon/segmentation.hpp"
#include "gaitmon/session.hpp"
#include "gaitmon/simulator.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

TissueSample tissue(Region region, double t_s, double d_mm = 1.0, double contact_s = 0.0) {
  TissueSample s;
  s.region = region;
  s.t_s = t_s;
  s.t_contact_start_s = contact_s;
  s.d_mm = d_mm;
  return s;
}

TEST(SimulationEffects, StressRelaxationRelaxesAHeldLoadTowardOneMinusStrength) {
  auto e = make_simulation_effect("stress_relaxation", {{"strength", 0.3}, {"tau_s", 0.2}});
  // A load of 100 N sampled every 10 ms from t = 0. The effect is called in contact only, so the
  // load is held from the frame before the first: the lag reaches 1 - exp(-(t + 0.01) / tau).
  double out = 0.0;
  for (int k = 0; k <= 19; ++k) out = e->tissue_force_n(tissue(Region::Heel, 0.01 * k), 100.0);
  EXPECT_NEAR(out, 100.0 - 30.0 * (1.0 - std::exp(-1.0)), 1e-9);  // at t + 0.01 = tau: 81.04 N
  for (int k = 20; k <= 400; ++k) out = e->tissue_force_n(tissue(Region::Heel, 0.01 * k), 100.0);
  EXPECT_NEAR(out, 70.0, 1e-6);
  // Another region has its own memory: at its first sample, one frame's lag.
  EXPECT_NEAR(e->tissue_force_n(tissue(Region::Met1_2, 4.0), 100.0),
              100.0 - 30.0 * (1.0 - std::exp(-0.01 / 0.2)), 1e-12);
}

TEST(SimulationEffects, StressRelaxationRecoversThroughTheSwing) {
  auto e = make_simulation_effect("stress_relaxation", {{"strength", 0.3}, {"tau_s", 0.2}});
  // Relaxed under 100 N up to t = 4 s; the next contact's first frame is at 4.5 s and
  // carries 50 N. The swing's frames are unloaded, so the lag decays from 100 N over the 0.49 s
  // up to the frame before, then takes one frame of 50 N.
  for (int k = 0; k <= 400; ++k) e->tissue_force_n(tissue(Region::Heel, 0.01 * k, 1.0, 0.0), 100.0);
  const double keep = std::exp(-0.01 / 0.2);
  const double held = 100.0 * (1.0 - std::exp(-4.01 / 0.2));
  const double lag = held * std::exp(-0.49 / 0.2) * keep + 50.0 * (1.0 - keep);
  EXPECT_NEAR(e->tissue_force_n(tissue(Region::Heel, 4.5, 1.0, 4.45), 50.0), 50.0 - 0.3 * lag,
              1e-9);
}

TEST(SimulationEffects, HysteresisRaisesLoadingAndLowersUnloadingRateIndependently) {
  auto e = make_simulation_effect("hysteresis", {{"strength", 0.1}, {"transition_mm", 0.25}});
  // From the unloaded state z = -1, compressing by 1 mm drives z to 1 - 2 exp(-4) whatever the
  // time step.
  const double up = e->tissue_force_n(tissue(Region::Heel, 0.01, 1.0), 200.0);
  EXPECT_NEAR(up, 200.0 * (1.0 + 0.1 * (1.0 - 2.0 * std::exp(-4.0))), 1e-9);
  // Holding the deformation keeps the state.
  EXPECT_DOUBLE_EQ(e->tissue_force_n(tissue(Region::Heel, 5.0, 1.0), 200.0), up);
  // Recovering by 2 mm: z = -1 + (z0 + 1) exp(-8).
  const double z0 = 1.0 - 2.0 * std::exp(-4.0);
  EXPECT_NEAR(e->tissue_force_n(tissue(Region::Heel, 5.01, -1.0), 200.0),
              200.0 * (1.0 + 0.1 * (-1.0 + (z0 + 1.0) * std::exp(-8.0))), 1e-9);
}

// The simulator calls its tissue effects in contact only, but the swing between two contacts
// unloads the tissue to d = 0. Reference: the closed forms of dz/dd = (sign(dd) - z) / d_s
// through the swing. Loading by 1 mm from the unloaded state (z = -1) gives
// z1 = 1 - 2 exp(-1 / d_s), unloading by 0.8 mm z2 = -1 + (z1 + 1) exp(-0.8 / d_s), by the last
// 0.2 mm in the swing z3 = -1 + (z2 + 1) exp(-0.2 / d_s), and loading from 0 to 0.5 mm in the
// next contact z = 1 - (1 - z3) exp(-0.5 / d_s).
TEST(SimulationEffects, HysteresisUnloadsThroughTheSwingBetweenContacts) {
  const double ds = 0.25;
  auto e = make_simulation_effect("hysteresis", {{"strength", 0.1}, {"transition_mm", ds}});
  e->tissue_force_n(tissue(Region::Heel, 0.01, 1.0, 0.0), 200.0);
  e->tissue_force_n(tissue(Region::Heel, 0.02, 0.2, 0.0), 200.0);
  const double z1 = 1.0 - 2.0 * std::exp(-1.0 / ds);
  const double z2 = -1.0 + (z1 + 1.0) * std::exp(-0.8 / ds);
  const double z3 = -1.0 + (z2 + 1.0) * std::exp(-0.2 / ds);
  const double z = 1.0 - (1.0 - z3) * std::exp(-0.5 / ds);
  EXPECT_NEAR(e->tissue_force_n(tissue(Region::Heel, 1.01, 0.5, 1.005), 200.0),
              200.0 * (1.0 + 0.1 * z), 1e-9);
}

TEST(SimulationEffects, ImpactTransientAddsAHalfSineAtHeelContactOnly) {
  auto e =
      make_simulation_effect("impact_transient", {{"amplitude_n", 90.0}, {"duration_s", 0.04}});
  EXPECT_NEAR(e->tissue_force_n(tissue(Region::Heel, 1.02, 1.0, 1.0), 10.0), 100.0, 1e-9);
  EXPECT_NEAR(e->tissue_force_n(tissue(Region::Heel, 1.01, 1.0, 1.0), 10.0),
              10.0 + 90.0 * std::sin(std::numbers::pi / 4.0), 1e-9);
  EXPECT_DOUBLE_EQ(e->tissue_force_n(tissue(Region::Heel, 1.05, 1.0, 1.0), 10.0), 10.0);
  EXPECT_DOUBLE_EQ(e->tissue_force_n(tissue(Region::Met3_5, 1.02, 1.0, 1.0), 10.0), 10.0);
}

TEST(SimulationEffects, SensorSaturationStopsReadingsAtTheCeiling) {
  auto e = make_simulation_effect("sensor_saturation", {{"ceiling_bits", 120.0}});
  EXPECT_DOUBLE_EQ(e->sensor_bits(SensorSample{}, 200.0), 120.0);
  EXPECT_DOUBLE_EQ(e->sensor_bits(SensorSample{}, 80.5), 80.5);
}

TEST(SimulationEffects, SensorCreepDriftsUpwardUnderAHeldLoad) {
  auto e = make_simulation_effect("sensor_creep", {{"gain", 0.2}, {"tau_s", 1.0}});
  double out = 0.0;
  for (int k = 0; k <= 100; ++k) out = e->sensor_bits({Foot::Left, 3, 0.01 * k}, 100.0);
  EXPECT_NEAR(out, 100.0 + 20.0 * (1.0 - std::exp(-1.0)), 1e-9);
  // The right foot's sensor 3 is another cell.
  EXPECT_DOUBLE_EQ(e->sensor_bits({Foot::Right, 3, 1.0}, 100.0), 100.0);
}

TEST(SimulationEffects, ThermalDriftRaisesEveryReadingLoadedOrNotAlongTheWarmUp) {
  auto e = make_simulation_effect("thermal_drift", {{"offset_bits", 8.0}, {"tau_s", 120.0}});
  EXPECT_DOUBLE_EQ(e->sensor_bits({Foot::Left, 0, 0.0}, 0.0), 0.0);
  // One time constant in: 8 (1 - 1/e) bits on an unloaded cell and on a loaded one alike.
  EXPECT_NEAR(e->sensor_bits({Foot::Left, 5, 120.0}, 0.0), 8.0 * (1.0 - std::exp(-1.0)), 1e-12);
  EXPECT_NEAR(e->sensor_bits({Foot::Right, 9, 120.0}, 50.0), 50.0 + 8.0 * (1.0 - std::exp(-1.0)),
              1e-12);
  // Early on the rise is offset / tau per second.
  EXPECT_NEAR(e->sensor_bits({Foot::Left, 0, 0.6}, 0.0), 0.6 * 8.0 / 120.0, 1e-4);
  EXPECT_NEAR(e->sensor_bits({Foot::Left, 0, 1e5}, 0.0), 8.0, 1e-9);
  EXPECT_THROW(make_simulation_effect("thermal_drift", {{"tau_s", 5.0}}), std::invalid_argument);
  EXPECT_THROW(make_simulation_effect("thermal_drift", {{"offset_bits", -1.0}}),
               std::invalid_argument);
}

TEST(SimulationEffects, CrosstalkAddsItsShareOfEachEdgeNeighboursReading) {
  const Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  const InsoleLayout layout(config.insole(InsoleSize::S41_42), config.sensor);
  auto e = make_simulation_effect("crosstalk", {{"coupling", 0.1}});
  // One loaded cell: it keeps its reading, each neighbour reads 0.1 of it per whole edge, and
  // no other cell reads anything.
  const std::size_t loaded = layout.region_sensors(Region::Heel)[5];
  std::vector<double> bits(layout.sensor_count(), 0.0);
  bits[loaded] = 100.0;
  e->sensor_frame(layout, bits);
  std::vector<double> expected(bits.size(), 0.0);
  expected[loaded] = 100.0;
  int neighbours = 0;
  for (const Neighbour& n : layout.neighbours(loaded)) {
    expected[n.sensor] = 10.0 * n.shared_edge;
    ++neighbours;
  }
  EXPECT_GE(neighbours, 3);
  for (std::size_t c = 0; c < bits.size(); ++c) EXPECT_NEAR(bits[c], expected[c], 1e-12) << c;
  // Two loaded cells next to each other: each reads the other's share on top of its own.
  const std::size_t other = layout.neighbours(loaded).front().sensor;
  const double shared = layout.neighbours(loaded).front().shared_edge;
  std::fill(bits.begin(), bits.end(), 0.0);
  bits[loaded] = 100.0;
  bits[other] = 40.0;
  e->sensor_frame(layout, bits);
  EXPECT_NEAR(bits[loaded], 100.0 + 0.1 * shared * 40.0, 1e-12);
  EXPECT_NEAR(bits[other], 40.0 + 0.1 * shared * 100.0, 1e-12);
  EXPECT_THROW(make_simulation_effect("crosstalk", {{"coupling", 0.3}}), std::invalid_argument);
}

// A session with crosstalk against the same seed without it, noise and dc bias off: every
// reading is the plain one plus its share of the neighbours' (to the rounding of both to bits),
// and the ring of cells around a contact reads where the plain session reads nothing.
TEST(SimulationEffects, ACrosstalkSessionReadsEachCellPlusItsNeighboursShare) {
  const Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  const InsoleLayout layout(config.insole(InsoleSize::S41_42), config.sensor);
  const auto dir = test::scratch_dir("sim-effects-crosstalk");
  SimulationOptions o;
  o.duration_s = 3.0;
  o.seed = 17;
  o.size = InsoleSize::S41_42;
  o.noise_sd_bits = 0.0;
  o.max_bias_bits = 0;
  simulate_session(config, o, dir / "plain.csv", dir / "plain.truth.json");
  o.effects = {"crosstalk"};
  o.effect_params["crosstalk"] = {{"coupling", 0.06}};
  simulate_session(config, o, dir / "xt.csv", dir / "xt.truth.json");
  SessionReader plain(dir / "plain.csv");
  SessionReader xt(dir / "xt.csv");
  Frame p, x;
  double worst = 0.0;
  long ring = 0;
  while (plain.next(p)) {
    ASSERT_TRUE(xt.next(x));
    for (std::size_t c = 0; c < p.bits.size(); ++c) {
      double expected = p.bits[c];
      for (const Neighbour& n : layout.neighbours(c))
        expected += 0.06 * n.shared_edge * p.bits[n.sensor];
      worst = std::max(worst, std::abs(x.bits[c] - std::min(255.0, expected)));
      if (p.bits[c] == 0 && x.bits[c] >= 3) ++ring;
    }
  }
  EXPECT_FALSE(xt.next(x));
  // Half a bit of the plain reading's rounding, its share of the neighbours' (at most 0.06 x 4
  // x 0.5), and half a bit of the crosstalk reading's own.
  EXPECT_LE(worst, 1.12);
  EXPECT_GT(ring, 100);
}

TEST(SimulationEffects, UnknownNamesAndParametersAndOutOfRangeValuesFailClearly) {
  try {
    make_simulation_effect("stress_relaxation", {{"tau", 0.1}});
    FAIL() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("unknown parameter 'tau'"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("tau_s"), std::string::npos);
  }
  try {
    make_simulation_effect("sensor_saturation", {{"ceiling_bits", 300.0}});
    FAIL() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("outside [60"), std::string::npos);
  }
  EXPECT_THROW(resolve_effect_params("none", {{"x", 1.0}}), std::invalid_argument);
  EXPECT_EQ(resolve_effect_params("sensor_creep", {}).at("tau_s"), 1.5);
}

TEST(SimulationEffects, SaturatedSessionNeverReadsAboveTheCeilingAndTheTruthSaysSo) {
  const Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  const auto dir = test::scratch_dir("sim-effects");
  SimulationOptions o;
  o.duration_s = 6.0;
  o.seed = 11;
  o.noise_sd_bits = 0.0;
  const auto max_reading = [&](const std::string& name) {
    simulate_session(config, o, dir / (name + ".csv"), dir / (name + ".truth.json"));
    SessionReader reader(dir / (name + ".csv"));
    Frame frame;
    int top = 0;
    while (reader.next(frame)) {
      for (auto b : frame.bits) top = std::max(top, static_cast<int>(b));
    }
    return top;
  };
  EXPECT_GT(max_reading("plain"), 100);
  o.effects = {"sensor_saturation"};
  o.effect_params["sensor_saturation"] = {{"ceiling_bits", 70.0}};
  // The ceiling plus the largest dc bias (2 bits).
  EXPECT_LE(max_reading("saturated"), 72);
  std::ifstream in(dir / "saturated.truth.json");
  const auto truth = nlohmann::json::parse(in);
  EXPECT_EQ(truth["options"]["effects"][0]["name"], "sensor_saturation");
  EXPECT_EQ(truth["options"]["effects"][0]["params"]["ceiling_bits"], 70.0);
}

TEST(SimulationEffects, StrongSensorCreepStillGivesOneStepPerStride) {
  // Creep of gain 0.4 and tau 0.5 s lifts the swings 145-190 summed bits above the quiet start
  // of the recording; the segmenter must raise its floor rather than merge the contacts (it
  // merged the right foot's into one 11.6-s contact before it watched for missed swings).
  const Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  const auto dir = test::scratch_dir("sim-effects-creep");
  SimulationOptions o;
  o.duration_s = 12.0;
  o.seed = 403;
  o.size = InsoleSize::S45_46;
  o.effects = {"sensor_creep"};
  o.effect_params["sensor_creep"] = {{"gain", 0.4}, {"tau_s", 0.5}};
  const SimulationTruth truth = simulate_session(config, o, dir / "c.csv", dir / "c.truth.json");
  std::vector<Step> steps;
  segment_session(dir / "c.csv", config, [&](Step&& s) { steps.push_back(std::move(s)); });
  const auto same_step = [](const Step& s, const SimulatedStep& t) {
    return s.foot == t.foot && std::abs(s.t_heel_strike_s - t.t_heel_strike_s) <= 0.021;
  };
  std::size_t whole = 0;
  for (const SimulatedStep& t : truth.steps) {
    // The creep's tail keeps a contact open up to 0.2 s after the stance: a stance ending later
    // than 0.3 s before the end of the recording may be cut by it.
    if (t.partial || t.t_toe_off_s > o.duration_s - 0.3) continue;
    ++whole;
    SCOPED_TRACE(std::string(foot_name(t.foot)) + " step at " + std::to_string(t.t_heel_strike_s));
    EXPECT_EQ(
        std::count_if(steps.begin(), steps.end(),
                      [&](const Step& s) { return s.status == StepStatus::Ok && same_step(s, t); }),
        1);
  }
  EXPECT_GE(whole, 20U);
  for (const Step& s : steps) {
    if (s.status != StepStatus::Ok) continue;
    EXPECT_TRUE(std::any_of(truth.steps.begin(), truth.steps.end(),
                            [&](const SimulatedStep& t) { return same_step(s, t); }))
        << foot_name(s.foot) << " step at " << s.t_heel_strike_s << " s was not simulated";
  }
}

}  // namespace
}  // namespace gaitmon
