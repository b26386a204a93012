// The discrepancy workflow on simulated sessions through the whole measurement chain (insole
// cells, segmentation, contact ellipses, per-step fits): prints the confusion matrix and the
// held-out gap shrink for each of the five effects the issue asks for, the thermal drift and
// none, three sessions each with different seeds, insole sizes and strengths, each force effect's
// also against the same session without it; and checks that it is deterministic end to end.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "gaitmon/batch.hpp"
#include "gaitmon/config.hpp"
#include "gaitmon/discrepancy.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/simulator.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

using test::shipped_config;

struct SessionCase {
  std::string effect;
  EffectParams params;
  InsoleSize size;
  std::uint64_t seed;
  // 12 s: about 20 complete steps, enough for 5 folds, and the whole matrix (33 sessions with
  // the paired ones) runs in about 35 s in a RelWithDebInfo build. A thermal drift needs a
  // minute: over 12 s the warm-up's rise is a bit or two.
  double duration_s = 12.0;
  double noise_sd_bits = SimulationOptions{}.noise_sd_bits;
  int max_bias_bits = SimulationOptions{}.max_bias_bits;
  double body_mass_kg = SimulationOptions{}.body_mass_kg;
  Rasterisation rasterisation = Rasterisation::CellCentre;
};

// Simulates the case into `dir`; returns the session CSV (and the truth, where asked).
std::filesystem::path simulated(const SessionCase& c, const std::filesystem::path& dir,
                                SimulationTruth* truth = nullptr) {
  SimulationOptions o;
  o.duration_s = c.duration_s;
  o.seed = c.seed;
  o.size = c.size;
  o.noise_sd_bits = c.noise_sd_bits;
  o.max_bias_bits = c.max_bias_bits;
  o.body_mass_kg = c.body_mass_kg;
  o.rasterisation = c.rasterisation;
  if (c.effect != "none") {
    o.effects = {c.effect};
    o.effect_params[c.effect] = c.params;
  }
  const auto csv = dir / fmt::format("{}-{}.csv", c.effect, c.seed);
  SimulationTruth made = simulate_session(shipped_config(), o, csv,
                                          dir / fmt::format("{}-{}.truth.json", c.effect, c.seed));
  if (truth != nullptr) *truth = std::move(made);
  return csv;
}

// The session at `csv` as the workflow reads it, each frame corrected first where `correct` is set.
DiscrepancyInput read_input(const std::filesystem::path& csv, InsoleSize size,
                            const std::function<void(Frame&)>& correct = {}) {
  const Config& config = shipped_config();
  std::vector<Step> steps;
  segment_session(
      csv, config, [&](Step&& s) { steps.push_back(std::move(s)); }, {}, correct);
  const InsoleLayout layout(config.insole(size), config.sensor);
  return prepare_discrepancy_input(steps, layout, config, discrepancy_analysis_settings());
}

DiscrepancyInput session_input(const SessionCase& c, const std::filesystem::path& dir,
                               SimulationTruth* truth = nullptr) {
  return read_input(simulated(c, dir, truth), c.size);
}

// `gaitmon discrepancy csv --out out options`: its stdout and DIR/discrepancy.json.
std::pair<std::string, nlohmann::json> discrepancy_cli(const std::filesystem::path& csv,
                                                       const std::filesystem::path& out,
                                                       const std::string& options) {
  std::string output;
  const int status = test::run_command(
      fmt::format("{} discrepancy {} --out {} {}", test::gaitmon_binary().string(), csv.string(),
                  out.string(), options),
      &output);
  EXPECT_EQ(status, 0) << output;
  std::ifstream in(out / "discrepancy.json");
  return {output, nlohmann::json::parse(in)};
}

// Reads `csv` again with a creep undone, as `gaitmon discrepancy` does.
ReadWithCreepUndone reader_of(const std::filesystem::path& csv, InsoleSize size) {
  return [csv, size](CreepCorrection creep) {
    return read_input(csv, size, [&](Frame& frame) { creep.undo(frame); });
  };
}

DiscrepancyResult run(const SessionCase& c, const std::filesystem::path& dir) {
  return find_discrepancy(session_input(c, dir));
}

TEST(DiscrepancySessions, ConfusionMatrixAndGapShrinkOnSimulatedSessions) {
  if (test::kSanitized) {
    GTEST_SKIP() << "18 simulated sessions with per-step Ceres fits take too long under the "
                    "sanitizers; the workflow's code runs under them in discrepancy_test";
  }
  const std::vector<InsoleSize> sizes{InsoleSize::S37_38, InsoleSize::S41_42, InsoleSize::S45_46};
  const std::map<std::string, std::vector<EffectParams>> strengths{
      {"none", {{}, {}, {}}},
      {"stress_relaxation",
       {{{"strength", 0.3}, {"tau_s", 0.3}},
        {{"strength", 0.45}, {"tau_s", 0.5}},
        {{"strength", 0.6}, {"tau_s", 1.0}}}},
      {"hysteresis",
       {{{"strength", 0.15}, {"transition_mm", 0.3}},
        {{"strength", 0.22}, {"transition_mm", 0.2}},
        {{"strength", 0.3}, {"transition_mm", 0.5}}}},
      {"impact_transient",
       {{{"amplitude_n", 80.0}, {"duration_s", 0.03}},
        {{"amplitude_n", 130.0}, {"duration_s", 0.04}},
        {{"amplitude_n", 200.0}, {"duration_s", 0.06}}}},
      {"sensor_saturation",
       {{{"ceiling_bits", 110.0}}, {{"ceiling_bits", 85.0}}, {{"ceiling_bits", 60.0}}}},
      {"sensor_creep",
       {{{"gain", 0.2}, {"tau_s", 1.0}},
        {{"gain", 0.3}, {"tau_s", 2.0}},
        {{"gain", 0.4}, {"tau_s", 0.5}}}},
      {"thermal_drift",
       {{{"offset_bits", 5.0}, {"tau_s", 120.0}},
        {{"offset_bits", 10.0}, {"tau_s", 120.0}},
        {{"offset_bits", 20.0}, {"tau_s", 300.0}}}},
      {"crosstalk", {{{"coupling", 0.05}}, {{"coupling", 0.06}}, {{"coupling", 0.1}}}},
  };
  const std::vector<std::string> classes{
      "none",         "stress_relaxation", "hysteresis", "impact_transient", "sensor_saturation",
      "sensor_creep", "thermal_drift",     "crosstalk"};
  const auto effect_sessions = static_cast<int>(3 * (classes.size() - 1));
  // The effects that the per-step zeroing takes out of the force and the zeros show instead.
  const auto in_zeros = [](const std::string& effect) {
    return effect == "sensor_creep" || effect == "thermal_drift";
  };
  const auto dir = test::scratch_dir("discrepancy-sessions");
  std::map<std::string, std::map<std::string, int>> named_matrix, ranked_matrix;
  std::string shrinks;
  // The sessions read again with the creep their zeros name undone.
  std::string undone;
  int wrong_names = 0;
  int none_named = 0;
  int right_names = 0;
  // Sessions whose zero level was reported drifting on a foot [0]: no, [1]: yes.
  std::array<int, 2> drift_in_zeros{}, drift_elsewhere{};
  std::map<std::string, double> min_zero_shrink{{"sensor_creep", 100.0}, {"thermal_drift", 100.0}};
  // The force effects against the same seed and size without the effect: what no extension can
  // take from the baseline (the paired session's own held-out NRMSE, its noise floor).
  std::string paired;
  // Each effect session with the effect at the simulator's own parameters: what the effect can
  // explain at all, against which the fitted candidate is judged.
  std::string at_truth;
  // The first named effect's parameters in each effect session, against the simulator's.
  std::string fitted;
  int beyond_any_extension = 0;
  int beyond_any_extension_in_n = 0;
  int at_issue_target = 0;
  int force_sessions = 0;
  double min_excess_removed = 100.0;
  std::uint64_t seed = 100;
  for (const std::string& effect : classes) {
    for (std::size_t i = 0; i < 3; ++i) {
      const SessionCase c{effect, strengths.at(effect)[i], sizes[i], ++seed,
                          effect == "thermal_drift" ? 60.0 : 12.0};
      const auto csv = simulated(c, dir);
      const DiscrepancyInput input = read_input(csv, c.size);
      const DiscrepancyResult r = find_discrepancy_undoing_creep(input, reader_of(csv, c.size));
      const std::string first = r.named_effects.empty() ? "none" : r.named_effects.front().name;
      ++named_matrix[effect][first];
      // Why the most likely candidate was not named, whenever it was not.
      EXPECT_EQ(
          r.not_named_reason.empty(),
          std::any_of(r.named_effects.begin(), r.named_effects.end(),
                      [&](const EffectEstimate& e) { return e.name == r.most_likely_candidate; }))
          << r.not_named_reason;
      std::size_t best = 0;
      for (std::size_t k = 1; k < r.candidates.size(); ++k) {
        if (r.candidates[k].heldout_deviance_drop > r.candidates[best].heldout_deviance_drop) {
          best = k;
        }
      }
      ++ranked_matrix[effect][r.candidates[best].name];
      if (effect == "none" && first != "none") ++none_named;
      if (effect != "none" && first != "none" && first != effect) ++wrong_names;
      if (effect != "none" && first == effect) ++right_names;
      std::string drifting;
      for (const ZeroLevelDrift& z : r.zero_levels) {
        if (z.drifting) drifting += foot_name(z.foot);
      }
      ++(in_zeros(effect) ? drift_in_zeros : drift_elsewhere)[!drifting.empty()];
      if (in_zeros(effect))
        min_zero_shrink[effect] = std::min(min_zero_shrink[effect], r.zero_gap_shrink_pct);
      std::string all_named;
      for (const EffectEstimate& e : r.named_effects) {
        all_named += (all_named.empty() ? "" : "+") + e.name;
      }
      // The creep the zeros name is undone in the readings and nothing is named on top of it
      // there; no other session names it (measured: the baseline held out 1.14 / 1.18 / 3.06 % as
      // read, 1.13 / 1.22 / 1.15 % with it undone).
      EXPECT_EQ(r.creep_undone.has_value(), effect == "sensor_creep") << all_named << c.seed;
      if (r.creep_undone) {
        EXPECT_EQ(all_named, "sensor_creep") << c.seed;
        undone += fmt::format(
            "  {:<18} {:<6} seed {:>3}: {} steps, the baseline held out {:.2f} % ({:.2f} % as "
            "read), most likely candidate there {}\n",
            effect, insole_size_name(c.size), c.seed, r.creep_undone->steps,
            r.creep_undone->baseline_heldout_nrmse_pct, r.baseline_heldout_nrmse_pct,
            r.creep_undone->most_likely_candidate);
      }
      shrinks += fmt::format(
          "  {:<18} {:<6} seed {:>3}: named {:<34} held-out {:6.2f} % -> {:6.2f} % (gap shrink "
          "{:5.1f} %); zero channel {:5.3f} % -> {:5.3f} % ({:5.1f} %); best candidate {} "
          "{:+.1f} % / zero {:+.1f} %; zero drifting: {}\n",
          effect, insole_size_name(c.size), c.seed, all_named.empty() ? "none" : all_named,
          r.baseline_heldout_nrmse_pct, r.extended_heldout_nrmse_pct, r.gap_shrink_pct,
          r.zero_baseline_heldout_nrmse_pct, r.zero_extended_heldout_nrmse_pct,
          r.zero_gap_shrink_pct, r.candidates[best].name, r.candidates[best].shrink_pct,
          r.candidates[best].zero_shrink_pct, drifting.empty() ? "-" : drifting);
      if (effect == "none") continue;
      std::string values;
      if (!r.named_effects.empty()) {
        for (const ParamEstimate& p : r.named_effects.front().params) {
          values += fmt::format(" {}={:.4g}+-{:.2g} (sandwich {:.2g})", p.name, p.value, p.se,
                                p.robust_se);
        }
      }
      std::string truths;
      for (const auto& [name, value] : c.params) truths += fmt::format(" {}={:.4g}", name, value);
      // Measured: 0.044 for 0.05, 0.046 for 0.06 and 0.091 for 0.1 (README: low even without
      // noise, and over a flat minimum).
      if (effect == "crosstalk" && !r.named_effects.empty()) {
        const double truth = c.params.at("coupling");
        EXPECT_NEAR(r.named_effects.front().params.at(0).value, truth, 0.25 * truth) << c.seed;
      }
      fitted += fmt::format("  {:<18} {:<6} seed {:>3}: {}{} (truth{})\n", effect,
                            insole_size_name(c.size), c.seed, first, values, truths);
      // The drift's candidate is linear: the simulator's warm-up as its mean rate over the
      // session, bits per minute.
      const EffectParams truth_params =
          effect == "thermal_drift"
              ? EffectParams{{"rate_bits_per_min",
                              60.0 * c.params.at("offset_bits") *
                                  -std::expm1(-c.duration_s / c.params.at("tau_s")) / c.duration_s}}
              : c.params;
      const FixedEffectEvaluation truth = evaluate_effect_at(input, effect, truth_params);
      const double truth_shrink =
          100.0 * (1.0 - truth.extended_nrmse_pct / truth.baseline_nrmse_pct);
      const double truth_zero_shrink =
          100.0 * (1.0 - truth.zero_extended_nrmse_pct / truth.zero_baseline_nrmse_pct);
      at_truth += fmt::format(
          "  {:<18} {:<6} seed {:>3}: at the true parameters {:5.1f} % (zero channel {:5.1f} %); "
          "fitted and held out {:5.1f} % ({:5.1f} %)\n",
          effect, insole_size_name(c.size), c.seed, truth_shrink, truth_zero_shrink,
          r.gap_shrink_pct, r.zero_gap_shrink_pct);
      // The fitted candidate, held out, comes within a fifth of what its effect explains at
      // the true parameters in sample (measured: 0.97 x at the least, creep's zero channel
      // 45-46; the impact and saturation of size 37-38 and saturation 41-42 and 45-46 gained
      // more as named, with a second effect on top, than the one effect at its truth).
      if (in_zeros(effect)) {
        EXPECT_GE(r.zero_gap_shrink_pct, 0.8 * truth_zero_shrink) << c.seed;
        continue;
      }
      EXPECT_GE(r.gap_shrink_pct, 0.8 * truth_shrink) << effect << " seed " << c.seed;
      ++force_sessions;
      const DiscrepancyResult without = run({"none", {}, c.size, c.seed}, dir);
      const double base = r.baseline_heldout_nrmse_pct;
      const double ext = r.extended_heldout_nrmse_pct;
      const double floor = without.baseline_heldout_nrmse_pct;
      EXPECT_LT(floor, base) << effect << " seed " << c.seed;
      const double max_shrink = 100.0 * (1.0 - floor / base);
      // The same floor in newtons on this session's scale. An effect that moves the peaks moves
      // the scale: the two bracket the ceiling, as the chain's error is partly proportional to
      // the force (the footprint) and partly not (the bits).
      const double floor_in_n = floor * without.nrmse_scale_n / r.nrmse_scale_n;
      const double max_shrink_in_n = 100.0 * (1.0 - floor_in_n / base);
      const double excess_removed =
          100.0 * (base * base - ext * ext) / (base * base - floor * floor);
      if (max_shrink < 40.0) ++beyond_any_extension;
      if (max_shrink_in_n < 40.0) ++beyond_any_extension_in_n;
      min_excess_removed = std::min(min_excess_removed, excess_removed);
      if (r.gap_shrink_pct >= 40.0) ++at_issue_target;
      // Every force effect but stress relaxation reaches the issue's 40 %, or all but a little
      // of what any extension could take (measured: hysteresis 45-46, whose ceiling is 28 %,
      // removed 110 % of the excess; saturation 41-42 reached 41.9 % and 92 %; crosstalk 0.05 at
      // size 37-38, where no extension could take more than 19 %, 96 %: 82 % before stop 42,
      // when the corrected readings kept the mixed ones' threshold).
      if (effect != "stress_relaxation") {
        EXPECT_TRUE(r.gap_shrink_pct >= 40.0 || excess_removed >= 85.0)
            << effect << " seed " << c.seed << ": " << r.gap_shrink_pct << " %, " << excess_removed
            << " % of the excess";
      }
      paired += fmt::format(
          "  {:<18} {:<6} seed {:>3}: without the effect {:5.2f} % (in newtons on this scale "
          "{:5.2f} %); the most any extension could shrink the gap {:5.1f} % ({:5.1f} %), shrunk "
          "{:5.1f} %; excess over the floor removed {:4.0f} %\n",
          effect, insole_size_name(c.size), c.seed, floor, floor_in_n, max_shrink, max_shrink_in_n,
          r.gap_shrink_pct, excess_removed);
    }
  }
  const auto print = [&](const char* title, std::map<std::string, std::map<std::string, int>>& m) {
    std::string out = fmt::format("{}\n{:<18}", title, "true \\ found");
    for (const auto& c : classes) out += fmt::format("{:>8.7}", c);
    out += "\n";
    for (const auto& row : classes) {
      out += fmt::format("{:<18}", row);
      for (const auto& col : classes) out += fmt::format("{:>8}", m[row][col]);
      out += "\n";
    }
    fmt::print("{}", out);
  };
  print("Confusion matrix (named effect; 3 sessions per row)", named_matrix);
  print("Best candidate by held-out likelihood (force and zero), named or not", ranked_matrix);
  fmt::print("Sessions:\n{}", shrinks);
  fmt::print("Read again with the sensor creep undone:\n{}", undone);
  fmt::print("Fitted parameters of the first effect named:\n{}", fitted);
  // The naming threshold (5 %) is 2.6 times the largest false improvement seen on 15 sessions
  // without an effect (these three and twelve others, README: impact_transient 1.95 %;
  // sensor_saturation gained up to 7.6 % in size 45-46, where no cells share the top reading,
  // and the ceiling rule keeps it unnamed), so none of these is named and no effect session is
  // named wrongly. All 18 effect sessions were named right when measured (sensor creep and the
  // thermal drift through the zero channel, the weakest impact through the heel's frames before
  // its footprint); the issue's 40 % shrink is not met by stress relaxation (README,
  // "Model-data discrepancy").
  fmt::print("effect sessions named right: {} of {}; with a wrong effect named: {}\n", right_names,
             effect_sessions, wrong_names);
  EXPECT_EQ(none_named, 0);
  EXPECT_EQ(wrong_names, 0);
  EXPECT_EQ(right_names, effect_sessions);
  // Creep and the drift are named on the zeros. Measured: creep's zero channel gap shrinks by
  // 72-78 %, the drift's by 27 % at its weakest (5 bits over 120 s: 1.9 bits a minute) and
  // 55-59 % at 3.6-3.9 bits a minute.
  fmt::print(
      "smallest zero channel shrink of the creep sessions: {:.1f} %, of the thermal drift "
      "sessions: {:.1f} %\n",
      min_zero_shrink["sensor_creep"], min_zero_shrink["thermal_drift"]);
  EXPECT_GE(min_zero_shrink["sensor_creep"], 40.0);
  EXPECT_GE(min_zero_shrink["thermal_drift"], 20.0);
  // What the zeroing takes out of the force still shows in the zero levels, and nothing else
  // moves them.
  fmt::print("zero level drifting: {} of 6 creep and thermal drift sessions, {} of {} others\n",
             drift_in_zeros[1], drift_elsewhere[1], drift_elsewhere[0] + drift_elsewhere[1]);
  EXPECT_EQ(drift_in_zeros[1], 6);
  EXPECT_EQ(drift_elsewhere[1], 0);
  // The gap shrink's ceiling: the same session without the effect still has its noise (areas,
  // cells, rounding), so an extension that models only the effect cannot shrink the gap by more
  // than 1 - floor / baseline (hysteresis also takes a little of the floor: two of its sessions
  // ended below it). When measured, that ceiling was under the issue's 40 % in one session
  // (hysteresis, size 45-46: 27.9 %, where the named effect reached the floor), and the named
  // effects removed 50-116 % of the squared excess over the floor (the least, 50-60 %, for
  // stress relaxation; 89 % or more for every other effect). With the floor in newtons the
  // ceilings move with the peaks: relaxation 35 / 33 / 43 %, hysteresis 45-46 44 %. The effect
  // at its true parameters (below) shows which is nearer: hysteresis 45-46 at its truth stays
  // at the floor on its own scale.
  fmt::print("Against the same seed and size without the effect (held-out NRMSE):\n{}", paired);
  fmt::print(
      "force effect sessions whose gap no extension could shrink by 40 %: {} of {} ({} with the "
      "floor in newtons); least excess over the floor removed: {:.0f} %; gap shrunk by 40 % or "
      "more: {} of {}\n",
      beyond_any_extension, force_sessions, beyond_any_extension_in_n, min_excess_removed,
      at_issue_target, force_sessions);
  EXPECT_GE(min_excess_removed, 33.0);
  fmt::print(
      "The effect at its true parameters (in sample) and as fitted (held out), gap shrink:\n{}",
      at_truth);
}

TEST(DiscrepancySessions, SameSessionGivesIdenticalDiscrepancyJson) {
  const auto dir = test::scratch_dir("discrepancy-determinism");
  SimulationOptions o;
  o.duration_s = 8.0;
  o.seed = 5;
  o.effects = {"impact_transient"};
  simulate_session(shipped_config(), o, dir / "s.csv", dir / "s.truth.json");
  std::string texts[2];
  for (int k = 0; k < 2; ++k) {
    const auto out = dir / fmt::format("out{}", k);
    const std::string command =
        fmt::format("{} discrepancy {} --out {} --report", test::gaitmon_binary().string(),
                    (dir / "s.csv").string(), out.string());
    std::string output;
    ASSERT_EQ(test::run_command(command, &output), 0) << output;
    std::ifstream in(out / "discrepancy.json");
    std::stringstream text;
    text << in.rdbuf();
    texts[k] = text.str();
    const auto j = nlohmann::json::parse(texts[k]);
    for (const char* key :
         {"named_effects", "baseline_heldout_nrmse_pct", "extended_heldout_nrmse_pct",
          "gap_shrink_pct", "where", "candidates"}) {
      EXPECT_TRUE(j.contains(key)) << key;
    }
    EXPECT_EQ(j["candidates"].size(), discrepancy_effect_names().size());
    EXPECT_GE(j["where"].size(), 1u);
    ASSERT_EQ(j["diagnostics"]["zero_levels"].size(), 2u);
    for (const auto& z : j["diagnostics"]["zero_levels"]) {
      EXPECT_FALSE(z["drifting"].get<bool>());
      // The course the report plots: one zero per step, in time order.
      ASSERT_EQ(z["zero_bits"].size(), z["steps"].get<std::size_t>());
      ASSERT_EQ(z["t_s"].size(), z["steps"].get<std::size_t>());
      const auto t = z["t_s"].get<std::vector<double>>();
      EXPECT_TRUE(std::is_sorted(t.begin(), t.end()));
    }
    EXPECT_EQ(output.find("zero level of foot"), std::string::npos) << output;
    std::ifstream html(out / "discrepancy.html");
    std::stringstream page;
    page << html.rdbuf();
    EXPECT_NE(page.str().find("<svg"), std::string::npos);
    EXPECT_NE(page.str().find("Zero level per foot"), std::string::npos);
    EXPECT_EQ(page.str().find("<script"), std::string::npos);
    // A parameter the data do not determine (saturation's ceiling above every reading here) has
    // no standard error: null in the JSON, "(no SE)" on the page, and never "nan".
    bool any_missing_se = false;
    for (const auto& c : j["candidates"]) {
      for (const auto& p : c["params"]) {
        any_missing_se = any_missing_se || p["se"].is_null();
      }
    }
    EXPECT_TRUE(any_missing_se);
    EXPECT_NE(page.str().find("(no SE)"), std::string::npos);
    EXPECT_EQ(page.str().find("nan"), std::string::npos);
  }
  EXPECT_EQ(texts[0], texts[1]);
}

TEST(DiscrepancySessions, NamesTheCreepOfAnInsoleFromItsZeros) {
  if (test::kSanitized) {
    GTEST_SKIP()
        << "a simulated session with per-step Ceres fits takes too long under the sanitizers; "
           "the zero channel runs under them in discrepancy_test";
  }
  // Creep of gain 0.3 and tau 2 s: the zeroing takes it out of the force, but the zero levels
  // rise by 3.7 % (left) and 6.5 % (right) of the peak when measured, and the zero channel names
  // it.
  const auto dir = test::scratch_dir("discrepancy-zero-levels");
  const auto csv =
      simulated({"sensor_creep", {{"gain", 0.3}, {"tau_s", 2.0}}, InsoleSize::S41_42, 402}, dir);
  std::string output;
  ASSERT_EQ(
      test::run_command(fmt::format("{} discrepancy {} --out {}", test::gaitmon_binary().string(),
                                    csv.string(), (dir / "out").string()),
                        &output),
      0)
      << output;
  EXPECT_NE(output.find("zero level of foot L"), std::string::npos) << output;
  EXPECT_NE(output.find("zero level of foot R"), std::string::npos) << output;
  std::ifstream in(dir / "out" / "discrepancy.json");
  const auto j = nlohmann::json::parse(in);
  ASSERT_EQ(j["diagnostics"]["zero_levels"].size(), 2u);
  for (const auto& z : j["diagnostics"]["zero_levels"]) {
    EXPECT_TRUE(z["drifting"].get<bool>()) << z.dump();
    EXPECT_GT(z["last_bits"].get<double>() - z["first_bits"].get<double>(), 40.0) << z.dump();
  }
  ASSERT_EQ(j["named_effects"].size(), 1u) << j["named_effects"].dump();
  EXPECT_EQ(j["named_effects"][0], "sensor_creep");
  EXPECT_GE(j["zero_channel"]["gap_shrink_pct"].get<double>(), 40.0) << j["zero_channel"].dump();
  EXPECT_NE(output.find("zero channel ("), std::string::npos) << output;
  // Named from the zeros, shown and determined there: analyze would undo it in the readings.
  EXPECT_NE(output.find("note: creep also reshapes each step's footprint"), std::string::npos)
      << output;
  // The NRMSE's scale in newtons, in the JSON and on stdout alike.
  const double scale_n = j["nrmse_scale"]["newtons"].get<double>();
  EXPECT_GT(scale_n, 50.0);
  EXPECT_NE(output.find(fmt::format("an NRMSE of 1 % is {:.2f} N RMS", scale_n / 100.0)),
            std::string::npos)
      << output;
  // The truth is gain 0.3 and tau 2 s (0.297 and 2.07 s when measured). The zero channel sees
  // the lag of the region's thresholded summed force rather than of each cell's reading, so
  // within 20 %.
  const auto& params = j["named_effect_params"][0]["params"];
  fmt::print("creep gain {} tau {}\n", params["gain"].dump(), params["tau_s"].dump());
  EXPECT_NEAR(params["gain"]["value"].get<double>(), 0.3, 0.06);
  EXPECT_NEAR(params["tau_s"]["value"].get<double>(), 2.0, 0.4);
  // The session was read again with the creep undone, and nothing is named on top of it.
  const auto& undone = j["creep_undone_in_readings"];
  ASSERT_TRUE(undone.is_object()) << undone.dump();
  EXPECT_EQ(undone["params"], params);
  EXPECT_EQ(j["second_candidates_on"], "the readings with the sensor creep undone");
  EXPECT_EQ(j["second_candidates"].size(), discrepancy_effect_names().size() - 1);
  for (const auto& c : j["second_candidates"]) EXPECT_NE(c["name"], "sensor_creep");
  EXPECT_NE(output.find("sensor creep undone in the readings (gain="), std::string::npos) << output;
}

// A creep and a relaxation together (size 41-42, cells read at their centres): fitted on the
// readings as read, the relaxation took up what the creep did to the footprints as well (strength
// 0.535, tau 0.38 s, for 0.45 and 0.5 s, when measured); on the readings with the creep undone it
// is named on top of the creep at 0.446 and 0.475 s, and the held-out gap shrinks more (30.0
// against 26.8 %).
TEST(DiscrepancySessions, AnEffectBesideACreepIsFittedOnTheReadingsWithTheCreepUndone) {
  if (test::kSanitized) {
    GTEST_SKIP() << "two runs of the workflow on a simulated session take too long under the "
                    "sanitizers; find_discrepancy_undoing_creep runs under them in "
                    "discrepancy_test";
  }
  const auto dir = test::scratch_dir("discrepancy-creep-and-relaxation");
  SimulationOptions o;
  o.duration_s = 12.0;
  o.seed = 131;
  o.size = InsoleSize::S41_42;
  o.effects = {"sensor_creep", "stress_relaxation"};
  o.effect_params["sensor_creep"] = {{"gain", 0.3}, {"tau_s", 1.0}};
  o.effect_params["stress_relaxation"] = {{"strength", 0.45}, {"tau_s", 0.5}};
  const auto csv = dir / "both.csv";
  simulate_session(shipped_config(), o, csv, dir / "both.truth.json");
  const auto relaxation = [](const nlohmann::json& j) {
    for (const auto& e : j["named_effect_params"]) {
      if (e["name"] == "stress_relaxation") return e["params"];
    }
    return nlohmann::json();
  };
  const auto [kept_out, kept] = discrepancy_cli(csv, dir / "kept", "--keep-creep");
  const nlohmann::json as_read = relaxation(kept);
  ASSERT_TRUE(as_read.is_object()) << kept_out;
  EXPECT_GT(as_read["strength"]["value"].get<double>(), 0.5) << kept_out;

  const auto [out, j] = discrepancy_cli(csv, dir / "undone", "");
  ASSERT_EQ(j["named_effects"].size(), 2u) << out;
  EXPECT_EQ(j["named_effects"][0], "sensor_creep") << out;
  EXPECT_EQ(j["named_effects"][1], "stress_relaxation") << out;
  const nlohmann::json undone = relaxation(j);
  EXPECT_NEAR(undone["strength"]["value"].get<double>(), 0.45, 0.045) << out;
  EXPECT_NEAR(undone["tau_s"]["value"].get<double>(), 0.5, 0.075) << out;
  EXPECT_GT(j["gap_shrink_pct"].get<double>(), kept["gap_shrink_pct"].get<double>()) << out;
}

// On cells that average, the creep's change of the footprint leaves the baseline a misfit that
// stress relaxation took up, named first (the coverage raster's creep session of size 37-38, as
// in the README's matrix on those cells). Read again with the creep its zeros name undone, the
// session shows no other effect: the baseline held out falls from 1.94 to 1.51 % when measured.
TEST(DiscrepancySessions, OnCellsThatAverageACreepUndoneInTheReadingsLeavesNoOtherEffect) {
  if (test::kSanitized) {
    GTEST_SKIP() << "two runs of the workflow on a simulated session take too long under the "
                    "sanitizers; find_discrepancy_undoing_creep runs under them in "
                    "discrepancy_test";
  }
  const auto dir = test::scratch_dir("discrepancy-coverage-creep");
  SessionCase c{"sensor_creep", {{"gain", 0.2}, {"tau_s", 1.0}}, InsoleSize::S37_38, 116};
  c.rasterisation = Rasterisation::Coverage;
  const auto csv = simulated(c, dir);
  const auto discrepancy = [&](const std::string& name, const std::string& options) {
    return discrepancy_cli(csv, dir / name, options);
  };
  const auto [kept_out, kept] = discrepancy("kept", "--keep-creep");
  ASSERT_GE(kept["named_effects"].size(), 1u) << kept_out;
  EXPECT_EQ(kept["named_effects"][0], "stress_relaxation") << kept_out;
  EXPECT_TRUE(kept["creep_undone_in_readings"].is_null());
  EXPECT_NE(kept_out.find("to the baseline (--keep-creep)"), std::string::npos) << kept_out;

  const auto [out, j] = discrepancy("undone", "");
  ASSERT_EQ(j["named_effects"].size(), 1u) << out;
  EXPECT_EQ(j["named_effects"][0], "sensor_creep") << out;
  const auto& undone = j["creep_undone_in_readings"];
  ASSERT_TRUE(undone.is_object()) << out;
  EXPECT_EQ(undone["params"], j["named_effect_params"][0]["params"]);
  EXPECT_EQ(undone["params"], kept["named_effect_params"][1]["params"]) << kept_out;
  // The same readings as read: the baseline and the zero channel do not change.
  EXPECT_EQ(j["baseline_heldout_nrmse_pct"], kept["baseline_heldout_nrmse_pct"]);
  EXPECT_EQ(j["zero_channel"], kept["zero_channel"]);
  const double as_read = j["baseline_heldout_nrmse_pct"].get<double>();
  const double there = undone["baseline_heldout_nrmse_pct"].get<double>();
  EXPECT_LT(there, 0.85 * as_read) << out;
  EXPECT_EQ(j["extended_heldout_nrmse_pct"].get<double>(), there);
  EXPECT_LT(j["extended_heldout_nrmse_pct"].get<double>(),
            kept["extended_heldout_nrmse_pct"].get<double>());
  // The relaxation that was the most likely as read is not named, and why is said.
  EXPECT_EQ(j["most_likely_candidate"], "stress_relaxation");
  EXPECT_NE(j["not_named_reason"].get<std::string>().find(
                "with the sensor creep that the zeros show undone in the readings"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("the extended figures above are of the readings with it undone"),
            std::string::npos)
      << out;
}

// Size 35-36 is not in the matrix. Without an effect its sessions gained 2.2-4.2 % with
// hysteresis when these two were chosen (ten seeds; met3_5's last frames at toe off), the closest
// any `none` session came to the 5 % naming threshold; these two were the highest (4.2 %, 4.0 %;
// 3.0 and 0.6 % since). Crosstalk gains 4.95 % in seed 201 since stop 42 (2.6 % before), under
// the 5 %, and the readings there show no crosstalk.
TEST(DiscrepancySessions, NothingIsNamedInTheSmallestSizeWithoutAnEffect) {
  if (test::kSanitized) {
    GTEST_SKIP() << "two simulated sessions with per-step Ceres fits take too long under the "
                    "sanitizers; the workflow's code runs under them in discrepancy_test";
  }
  const auto dir = test::scratch_dir("discrepancy-size-35-36");
  for (const std::uint64_t seed : {201u, 506u}) {
    const DiscrepancyResult r = run({"none", {}, InsoleSize::S35_36, seed}, dir);
    double best = -100.0;
    std::string best_name;
    for (const CandidateResult& c : r.candidates) {
      if (c.shrink_pct > best) {
        best = c.shrink_pct;
        best_name = c.name;
      }
    }
    fmt::print("size 35-36 seed {}: held-out {:.2f} %, best candidate {} {:+.1f} %\n", seed,
               r.baseline_heldout_nrmse_pct, best_name, best);
    EXPECT_TRUE(r.named_effects.empty()) << "seed " << seed << ": " << r.named_effects.front().name;
  }
}

// A light walker's heel takes its load too gently for its cells to give a footprint in the
// first frames (at 25 kg up to 171 N before the first). Those frames, where the model has no
// area and says nothing, were compared as an impact's, and these sessions without an effect
// named impact_transient (78-98 N over 13-20 ms, gap 36-51 %).
// At 20 and 25 kg the threshold by the seed's rule alone was under one bit and took noise for
// contact: hysteresis was named in three of these four sessions (strength 0.10-0.62). At 25-30 kg
// the heel's frames before its first footprint were taken for an impact.
TEST(DiscrepancySessions, NothingIsNamedForALightWalkerWithoutAnEffect) {
  if (test::kSanitized) {
    GTEST_SKIP() << "six simulated sessions with per-step Ceres fits take too long under the "
                    "sanitizers; the workflow's code runs under them in discrepancy_test";
  }
  const auto dir = test::scratch_dir("discrepancy-light-walker");
  for (const auto& [mass, seed] : {std::pair{20.0, 3u}, std::pair{20.0, 4u}, std::pair{25.0, 3u},
                                   std::pair{25.0, 4u}, std::pair{30.0, 3u}, std::pair{30.0, 4u}}) {
    SessionCase c{"none", {}, InsoleSize::S41_42, seed};
    c.body_mass_kg = mass;
    const DiscrepancyResult r = run(c, dir);
    fmt::print("{} kg, seed {}: named {}\n", mass, seed,
               r.named_effects.empty() ? "none" : r.named_effects.front().name);
    EXPECT_TRUE(r.named_effects.empty())
        << mass << " kg, seed " << seed << ": " << r.named_effects.front().name;
  }
}

// On cells that average the pressure over their area (the coverage raster) the footprint
// over-reads the contact, and a rim cell's share of its neighbours' load reads as crosstalk: with
// the footprint, the matrix's sessions named crosstalk first in 14 of the 21 without it, two of the
// three `none` among them. `discrepancy`'s default, --area auto, weighs how the cells read, as
// analyze does, and fits footprint-mean there. That left crosstalk named first in four sessions of
// size 41-42, this `none` session among them: the partly covered rim raises the share of the
// neighbours' readings as crosstalk does. Crosstalk is now named only where the cells' readings
// also fit their caps best with a coupling undone, which here they do not, with either area.
TEST(DiscrepancySessions, OnCellsThatAverageTheAreaTheyCallForLeavesCrosstalkUnnamed) {
  if (test::kSanitized) {
    GTEST_SKIP()
        << "two runs of the workflow on a simulated session take too long under the sanitizers; "
           "how the cells read runs under them in AnalyzeCommand, the workflow in "
           "discrepancy_test";
  }
  const auto dir = test::scratch_dir("discrepancy-coverage");
  SessionCase c{"none", {}, InsoleSize::S41_42, 102};
  c.rasterisation = Rasterisation::Coverage;
  const auto csv = simulated(c, dir);
  const auto discrepancy = [&](const std::string& name, const std::string& options) {
    return discrepancy_cli(csv, dir / name, options);
  };
  const std::string unseen = "the cells show no crosstalk (their readings fit their caps best";
  const auto [auto_out, chosen] = discrepancy("auto", "");
  EXPECT_NE(auto_out.find("the cells average the pressure (footprint-mean); area footprint-mean "
                          "(auto)"),
            std::string::npos)
      << auto_out;
  EXPECT_EQ(chosen["settings"]["area"], "footprint-mean");
  EXPECT_EQ(auto_out.find("note: creep"), std::string::npos) << auto_out;
  EXPECT_EQ(chosen["settings"]["area_auto"], true);
  EXPECT_EQ(chosen["settings"]["min_cell_coupling"], 0.03);
  EXPECT_EQ(chosen["cell_reading"]["favoured"], "mean");
  EXPECT_LT(chosen["cell_reading"]["crosstalk_coupling"].get<double>(), 0.03);
  EXPECT_EQ(chosen["diagnostics"]["cell_coupling"]["coupling"],
            chosen["cell_reading"]["crosstalk_coupling"]);
  EXPECT_EQ(chosen["diagnostics"]["cell_coupling"]["frames"], chosen["cell_reading"]["frames"]);
  EXPECT_GE(chosen["diagnostics"]["neighbour_share"]["floor"].get<double>(), 0.005);
  EXPECT_TRUE(chosen["named_effects"].empty()) << chosen["named_effects"].dump();
  EXPECT_EQ(chosen["most_likely_candidate"], "crosstalk") << auto_out;
  EXPECT_NE(auto_out.find(unseen), std::string::npos) << auto_out;
  const auto [footprint_out, footprint] = discrepancy("footprint", "--area footprint");
  EXPECT_EQ(footprint["settings"]["area"], "footprint");
  EXPECT_EQ(footprint["settings"]["area_auto"], false);
  EXPECT_NE(footprint_out.find("note: the footprint over-reads averaging cells"), std::string::npos)
      << footprint_out;
  EXPECT_EQ(auto_out.find("note: "), std::string::npos) << auto_out;
  for (const auto& name : footprint["named_effects"]) EXPECT_NE(name, "crosstalk");
  EXPECT_EQ(footprint["most_likely_candidate"], "crosstalk") << footprint_out;
  EXPECT_NE(footprint_out.find(unseen), std::string::npos) << footprint_out;
  EXPECT_GT(footprint["baseline_heldout_nrmse_pct"].get<double>(),
            2.0 * chosen["baseline_heldout_nrmse_pct"].get<double>());
}

TEST(DiscrepancySessions, RelaxationWhoseStrengthAndTauTradeOffIsRefinedToItsMinimum) {
  if (test::kSanitized) {
    GTEST_SKIP()
        << "a simulated session with per-step Ceres fits takes too long under the sanitizers; "
           "the relaxation candidate's search runs under them in discrepancy_test";
  }
  // Strength and tau trade off along a valley of the deviance. The coordinate search used
  // before stepped along the axes only, by half the grid's first spacing (15 ms for tau), and
  // stopped off the valley's floor: the curvature there was not positive definite, no standard
  // error came out, and this session (16 % held-out gain, BIC 680 better) went unnamed.
  const auto dir = test::scratch_dir("discrepancy-relaxation-valley");
  const DiscrepancyResult r =
      run({"stress_relaxation", {{"strength", 0.6}, {"tau_s", 1.0}}, InsoleSize::S41_42, 105}, dir);
  ASSERT_FALSE(r.named_effects.empty());
  const EffectEstimate& named = r.named_effects.front();
  EXPECT_EQ(named.name, "stress_relaxation");
  for (const ParamEstimate& p : named.params) {
    EXPECT_TRUE(std::isfinite(p.se)) << p.name;
    const double truth = p.name == "strength" ? 0.6 : 1.0;
    EXPECT_NEAR(p.value, truth, p.name == "strength" ? 0.05 : 0.4) << p.name;
  }
  EXPECT_GE(r.gap_shrink_pct, 10.0);
}

// Why no relaxation session of the matrix gets near its paired session's floor, even at the
// effect's true parameters: relaxation lowers the pressure under the same contact, and the cells'
// rounded readings give the footprint less precisely than in the session without it, so the
// relaxed session's own floor is higher. Measured without sensor noise or dc bias (rounding
// alone), against the simulator's planned contact area: the footprint's RMS relative error over
// every frame it is determined in, and its mean, per region.
TEST(DiscrepancySessions, RelaxationLowersThePressureAndSoThePrecisionOfTheFootprint) {
  const auto dir = test::scratch_dir("discrepancy-relaxation-footprint");
  struct FootprintCheck {
    double rms = 0.0, mean = 0.0;
    std::map<std::pair<Foot, long>, double> force_n;  // by foot and frame
  };
  const auto footprint_check = [&](const SessionCase& c) {
    SimulationTruth truth;
    const DiscrepancyInput input = session_input(c, dir, &truth);
    std::array<FootprintCheck, kRegionCount> out{};
    for (Region region : kRegions) {
      const std::size_t ri = index_of(region);
      double sum = 0.0, sum2 = 0.0;
      int n = 0;
      for (const DiscrepancyStep& ds : input.steps) {
        const StepAnalysis& sa = ds.analysis;
        const auto planned =
            std::find_if(truth.steps.begin(), truth.steps.end(), [&](const auto& t) {
              return t.foot == sa.foot && std::abs(t.t_heel_strike_s - sa.t_heel_strike_s) < 0.05;
            });
        if (planned == truth.steps.end()) continue;
        const double duration_s = planned->t_contact_end_s - planned->t_contact_start_s;
        const RegionSeries& series = sa.at(region).series;
        for (std::size_t i = 0; i < series.t_s.size(); ++i) {
          if (!(series.area_mm2[i] > 0.0)) continue;
          const double fraction = (series.t_s[i] - planned->t_contact_start_s) / duration_s;
          const double area = planned_contact_area_mm2(truth.regions[ri], region, fraction).first;
          if (!(area > 0.0)) continue;
          const double e = series.area_mm2[i] / area - 1.0;
          out[ri].force_n[{sa.foot, std::lround(series.t_s[i] * truth.sample_rate_hz)}] =
              series.force_n[i];
          sum += e;
          sum2 += e * e;
          ++n;
        }
      }
      if (n > 0) {
        out[ri].rms = std::sqrt(sum2 / n);
        out[ri].mean = sum / n;
      }
    }
    return out;
  };
  SessionCase none{"none", {}, InsoleSize::S41_42, 105};
  none.noise_sd_bits = 0.0;
  none.max_bias_bits = 0;
  SessionCase relaxed = none;
  relaxed.effect = "stress_relaxation";
  relaxed.params = {{"strength", 0.45}, {"tau_s", 0.5}};
  const auto without = footprint_check(none);
  const auto with = footprint_check(relaxed);
  for (Region region : {Region::Heel, Region::MidfootPosterior, Region::MidfootAnterior,
                        Region::Met1_2, Region::Met3_5}) {
    const std::size_t ri = index_of(region);
    // The force at the same frames, where both sessions determine the footprint.
    double ratio_sum = 0.0;
    int frames = 0;
    for (const auto& [frame, force] : with[ri].force_n) {
      const auto there = without[ri].force_n.find(frame);
      if (there == without[ri].force_n.end()) continue;
      ratio_sum += force / there->second;
      ++frames;
    }
    ASSERT_GT(frames, 100) << region_name(region);
    const double force_ratio = ratio_sum / frames;
    fmt::print(
        "{:18} footprint area error RMS {:.4f} -> {:.4f} with relaxation (mean {:+.4f} -> "
        "{:+.4f}); force at the same frames x {:.3f}\n",
        region_name(region), without[ri].rms, with[ri].rms, without[ri].mean, with[ri].mean,
        force_ratio);
    EXPECT_LT(force_ratio, 0.95) << region_name(region);
    EXPECT_GT(with[ri].rms, without[ri].rms) << region_name(region);
    // Scatter, not a bias that the per-step stiffness could take up.
    EXPECT_LT(std::abs(with[ri].mean), 0.01) << region_name(region);
  }
  // In the midfoot's front and under the metatarsals the error grows by a third or more (0.81-0.85
  // of the force there; at the heel, with 0.81 of it, by less, over its many more cells).
  for (Region region : {Region::MidfootAnterior, Region::Met1_2, Region::Met3_5}) {
    EXPECT_GT(with[index_of(region)].rms, 1.3 * without[index_of(region)].rms)
        << region_name(region);
  }
}

// Crosstalk is named only where the readings show it, and too few cells beside a load cannot:
// the matrix's crosstalk session of size 41-42, with its count of such cell-frames taken under
// the 1000 the share needs, names no crosstalk and says why. Nor where the cells' own readings
// fit their caps best with less than 0.03 undone, or no region-frame weighed them.
TEST(DiscrepancySessions, CrosstalkIsNotNamedWhereTooFewCellsCanShowIt) {
  if (test::kSanitized) {
    GTEST_SKIP() << "a simulated session with per-step Ceres fits takes too long under the "
                    "sanitizers; the candidate's code runs under them in discrepancy_effects_test";
  }
  const auto dir = test::scratch_dir("discrepancy-crosstalk-cells");
  DiscrepancyInput input =
      session_input({"crosstalk", {{"coupling", 0.06}}, InsoleSize::S41_42, 123}, dir);
  const DiscrepancyResult shown = find_discrepancy(input);
  ASSERT_FALSE(shown.named_effects.empty());
  EXPECT_EQ(shown.named_effects.front().name, "crosstalk");
  EXPECT_NEAR(input.cell_coupling.coupling, 0.06, 0.012);
  EXPECT_GE(input.cell_coupling.frames, 50);
  const auto unnamed = [](const DiscrepancyInput& changed, const std::string& why) {
    const DiscrepancyResult r = find_discrepancy(changed);
    for (const EffectEstimate& e : r.named_effects) EXPECT_NE(e.name, "crosstalk") << why;
    EXPECT_EQ(r.most_likely_candidate, "crosstalk");
    EXPECT_NE(r.not_named_reason.find(why), std::string::npos) << r.not_named_reason;
  };
  DiscrepancyInput still = input;
  still.cell_coupling.coupling = 0.029;
  unnamed(still,
          "the cells show no crosstalk (their readings fit their caps best with a coupling "
          "of 0.029 undone, where 0.03 is needed)");
  still.cell_coupling = {0.06, 0};
  unnamed(still, "no region-frame has 8 cells over the threshold");
  ASSERT_GE(input.neighbour_share.cell_frames, kMinNeighbourShareCellFrames);
  input.neighbour_share.cell_frames = kMinNeighbourShareCellFrames - 1;
  unnamed(input, "too few cells next to loaded ones (999 cell-frames, 1000 needed)");
}

// `gaitmon analyze --effects crosstalk` measures the steps again at the candidate's couplings
// and fits the coupling of the matrix's 41-42 crosstalk session: 0.046 there, against the
// simulator's 0.06 (the matrix holds every size to a quarter of its coupling). Without
// --effects, analyze says that the cells show crosstalk (0.058 undone).
TEST(DiscrepancySessions, AnalyzeFitsTheCouplingOfACrosstalkSession) {
  if (test::kSanitized) {
    GTEST_SKIP() << "a simulated session with per-step Ceres fits takes too long under the "
                    "sanitizers; the candidate's code runs under them in discrepancy_effects_test";
  }
  const auto dir = test::scratch_dir("discrepancy-analyze-crosstalk");
  const auto csv = simulated({"crosstalk", {{"coupling", 0.06}}, InsoleSize::S41_42, 123}, dir);
  std::string output;
  ASSERT_EQ(test::run_command(
                fmt::format("{} analyze {} --out {} --effects crosstalk",
                            test::gaitmon_binary().string(), csv.string(), (dir / "out").string()),
                &output),
            0)
      << output;
  std::ifstream in(dir / "out" / "session.json");
  const auto extended = nlohmann::json::parse(in).at("extended_model");
  ASSERT_EQ(extended.at("effects").size(), 1u) << extended.dump();
  EXPECT_EQ(extended["effects"][0]["name"], "crosstalk");
  const auto& coupling = extended["effects"][0]["params"]["coupling"];
  fmt::print("analyze --effects crosstalk: coupling {}\n", coupling.dump());
  EXPECT_NEAR(coupling["value"].get<double>(), 0.06, 0.25 * 0.06);
  EXPECT_GT(coupling["se"].get<double>(), 0.0);
  EXPECT_LT(extended["extended_heldout_nrmse_pct"].get<double>(),
            0.6 * extended["baseline_heldout_nrmse_pct"].get<double>())
      << extended.dump();
  // Without the effect, the summary says that the cells show crosstalk and how to fit it.
  const std::string note = "note: the cells' readings fit their caps best with a crosstalk of 0.0";
  EXPECT_EQ(output.find(note), std::string::npos) << output;
  std::string baseline;
  ASSERT_EQ(test::run_command(fmt::format("{} analyze {} --out {}", test::gaitmon_binary().string(),
                                          csv.string(), (dir / "baseline").string()),
                              &baseline),
            0)
      << baseline;
  EXPECT_NE(baseline.find(note), std::string::npos) << baseline;
  EXPECT_NE(baseline.find("--effects crosstalk fits it"), std::string::npos) << baseline;
}

// A 12-s session of size 41-42 with `first` and crosstalk at a coupling of 0.08, in the
// simulator's order, prepared for the extended model.
DiscrepancyInput with_crosstalk(const std::string& first, const EffectParams& params,
                                std::uint64_t seed, const std::filesystem::path& dir) {
  const Config& config = shipped_config();
  SimulationOptions o;
  o.duration_s = 12.0;
  o.size = InsoleSize::S41_42;
  o.seed = seed;
  o.effects = {first, "crosstalk"};
  o.effect_params[first] = params;
  o.effect_params["crosstalk"] = {{"coupling", 0.08}};
  const auto csv = dir / (first + ".csv");
  simulate_session(config, o, csv, dir / (first + ".truth.json"));
  std::vector<Step> steps;
  segment_session(csv, config, [&](Step&& s) { steps.push_back(std::move(s)); });
  const InsoleLayout layout(config.insole(o.size), config.sensor);
  return prepare_discrepancy_input(steps, layout, config, discrepancy_analysis_settings());
}

std::string fitted_values(const ExtendedModelFit& fit) {
  std::string values;
  for (const EffectEstimate& e : fit.effects) {
    for (const ParamEstimate& p : e.params) values += fmt::format(" {}={:.4g}", p.name, p.value);
  }
  return values + fmt::format("; held-out {:.2f} % -> {:.2f} %", fit.baseline_heldout_nrmse_pct,
                              fit.extended_heldout_nrmse_pct);
}

// Two effects at once, fitted together as `analyze --effects` does. Fitted one after the other,
// the first took up the second's share: hysteresis 0.43 for 0.2 and a ceiling of 104 bits for
// 85, where crosstalk had widened the footprint and mixed the neighbours into the capped cells.
// Refitted with the second in place, seeing the contact as crosstalk corrects it, they come out
// at 0.21 and 85 bits (measured).
TEST(DiscrepancySessions, TwoEffectsFittedTogetherRecoverBoth) {
  if (test::kSanitized) {
    GTEST_SKIP() << "two simulated sessions with per-step Ceres fits take too long under the "
                    "sanitizers; the candidates' code runs under them in discrepancy_effects_test";
  }
  const auto dir = test::scratch_dir("discrepancy-two-effects");
  struct Case {
    std::string first;
    EffectParams params;
    std::uint64_t seed;
  };
  for (const Case& c : {Case{"hysteresis", {{"strength", 0.2}, {"transition_mm", 0.3}}, 142},
                        Case{"sensor_saturation", {{"ceiling_bits", 85.0}}, 131}}) {
    SCOPED_TRACE(c.first);
    const std::vector<std::string> effects{c.first, "crosstalk"};
    const ExtendedModelFit fit =
        fit_extended_model(with_crosstalk(c.first, c.params, c.seed, dir), effects);
    ASSERT_EQ(fit.effects.size(), 2u);
    fmt::print("{} with crosstalk 0.08:{}\n", c.first, fitted_values(fit));
    const double first = fit.effects[0].params[0].value;
    const double truth = c.params.begin()->second;  // strength, or ceiling_bits
    // Refitted on the contact as measured instead, the ceiling came out at 82.5 bits.
    EXPECT_NEAR(first, truth, (c.first == "hysteresis" ? 0.15 : 0.02) * truth);
    EXPECT_NEAR(fit.effects[1].params[0].value, 0.08, 0.25 * 0.08);
    EXPECT_LT(fit.extended_heldout_nrmse_pct, 0.45 * fit.baseline_heldout_nrmse_pct);
  }
}

// An effect listed that the data do not show (`analyze --effects`): sensor creep, absent from
// the session, ends at its bounds without a standard error. The refit of the others must not
// wait for it to have one: when it did, the ceiling stayed at 104 bits for 85 (measured).
TEST(DiscrepancySessions, AnEffectTheDataDoNotShowDoesNotHoldBackTheRefitOfTheOthers) {
  if (test::kSanitized) {
    GTEST_SKIP()
        << "three effects refitted on a simulated session take too long under the sanitizers; "
           "the refit with a second effect runs under them in discrepancy_test";
  }
  const auto dir = test::scratch_dir("discrepancy-absent-effect");
  const std::vector<std::string> effects{"sensor_saturation", "crosstalk", "sensor_creep"};
  const ExtendedModelFit fit = fit_extended_model(
      with_crosstalk("sensor_saturation", {{"ceiling_bits", 85.0}}, 131, dir), effects);
  ASSERT_EQ(fit.effects.size(), 3u);
  fmt::print("saturation 85 bits and crosstalk 0.08, creep listed:{}\n", fitted_values(fit));
  ASSERT_TRUE(std::any_of(fit.effects[2].params.begin(), fit.effects[2].params.end(),
                          [](const ParamEstimate& p) { return !std::isfinite(p.se); }))
      << "the creep was determined; the test needs an effect that is not";
  EXPECT_NEAR(fit.effects[0].params[0].value, 85.0, 0.02 * 85.0);
  EXPECT_NEAR(fit.effects[1].params[0].value, 0.08, 0.25 * 0.08);
  EXPECT_LT(fit.extended_heldout_nrmse_pct, 0.45 * fit.baseline_heldout_nrmse_pct);
}

TEST(DiscrepancySessions, ACandidateWhoseParametersTheDataDoNotDetermineIsNotNamed) {
  // On this real recording (8 force sensors a foot spread over patches of cells, no contact
  // area to speak of) the impact candidate lowers the held-out force error by more than the 5 %
  // threshold and BIC by hundreds, but its duration goes to the top of its range and its
  // amplitude with it: an optimum on a bound, without a finite standard error, is not an effect
  // the data show, so it is not named. Crosstalk gains more still (the correction shrinks the
  // patches' footprints: 17 % at a coupling of 0.19; 40-44 % at the top of its range while its
  // residual was on the corrected force's scale), but the readings show none: the cells around
  // a patch read nothing. What is named is the most likely candidate that passes: creep, from
  // the zeros, as on the project's two other real recordings.
  if (test::kSanitized) {
    GTEST_SKIP() << "the whole workflow on a real recording takes six minutes under TSan; "
                    "its code runs under the sanitizers in discrepancy_test";
  }
  const auto dir = test::scratch_dir("discrepancy-undetermined");
  const auto csv = test::shared_dir() / "real-data" / "gaitpdb" / "gaitpdb_GaCo01_01.csv";
  if (!std::filesystem::exists(csv)) GTEST_SKIP() << "real recording not found: " << csv;
  std::string output;
  ASSERT_EQ(
      test::run_command(fmt::format("{} discrepancy {} --out {}", test::gaitmon_binary().string(),
                                    csv.string(), (dir / "out").string()),
                        &output),
      0)
      << output;
  std::ifstream in(dir / "out" / "discrepancy.json");
  const auto j = nlohmann::json::parse(in);
  ASSERT_FALSE(j["named_effects"].empty());
  for (const auto& e : j["named_effects"]) EXPECT_NE(e, "impact_transient") << e.dump();
  EXPECT_EQ(j["named_effects"][0], "sensor_creep");
  EXPECT_GE(j["zero_channel"]["gap_shrink_pct"].get<double>(), 10.0) << j["zero_channel"].dump();
  EXPECT_NE(output.find("named: sensor_creep gain="), std::string::npos) << output;
  // The creep is undone in the readings and they are read again; crosstalk is a candidate there
  // too, and not named for the same reason.
  EXPECT_NE(output.find("(the most likely candidate, crosstalk, is not named: with the sensor "
                        "creep that the zeros show undone in the readings, the readings show no "
                        "crosstalk"),
            std::string::npos)
      << output;
  ASSERT_TRUE(j["creep_undone_in_readings"].is_object()) << output;
  EXPECT_EQ(j["creep_undone_in_readings"]["most_likely_candidate"], "crosstalk") << output;
  EXPECT_EQ(j["most_likely_candidate"], "crosstalk");
  EXPECT_LT(j["diagnostics"]["neighbour_share"]["floor"].get<double>(), 0.005);
  bool seen = false;
  for (const auto& c : j["candidates"]) {
    if (c["name"] != "impact_transient") continue;
    seen = true;
    EXPECT_GE(c["heldout_shrink_pct"].get<double>(), 5.0) << c.dump();
    EXPECT_LE(c["delta_bic"].get<double>(), -10.0) << c.dump();
    EXPECT_NEAR(c["params"]["duration_s"]["value"].get<double>(), 0.2, 1e-9) << c.dump();
    EXPECT_TRUE(c["params"]["duration_s"]["se"].is_null()) << c.dump();
  }
  EXPECT_TRUE(seen);
}

}  // namespace
}  // namespace gaitmon
