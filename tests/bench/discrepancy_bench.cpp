// The discrepancy workflow on a 60-second two-foot simulated session (target: 60 s): the
// segmentation, the per-step fits and the candidate search, as `gaitmon discrepancy` runs them,
// on sessions with a hidden effect (so a second effect is searched for too) and without one.
#include <benchmark/benchmark.h>
#include <fmt/format.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "gaitmon/batch.hpp"
#include "gaitmon/discrepancy.hpp"
#include "gaitmon/simulator.hpp"
#include "gaitmon/types.hpp"
#include "test_support.hpp"

namespace {

namespace fs = std::filesystem;

const gaitmon::Config& config() {
  static const gaitmon::Config c = gaitmon::load_config(gaitmon::default_config_path());
  return c;
}

// One 60-s session: the effect (none for none) with its parameters, on an insole size.
struct Session {
  std::string effect;
  gaitmon::EffectParams params;
  gaitmon::InsoleSize size = gaitmon::InsoleSize::S37_38;
  std::uint64_t seed = 3;
};

fs::path simulated(const Session& s) {
  static const fs::path dir = gaitmon::test::scratch_dir("discrepancy_bench");
  const fs::path csv =
      dir / fmt::format("{}-{}-{}-60.csv", s.effect, gaitmon::insole_size_name(s.size), s.seed);
  if (!fs::exists(csv)) {
    gaitmon::SimulationOptions options;
    options.duration_s = 60.0;
    options.seed = s.seed;
    options.size = s.size;
    if (s.effect != "none") {
      options.effects = {s.effect};
      options.effect_params[s.effect] = s.params;
    }
    gaitmon::simulate_session(config(), options, csv, fs::path(csv).replace_extension(".json"));
  }
  return csv;
}

void run(benchmark::State& state, const Session& session) {
  const fs::path csv = simulated(session);
  const gaitmon::InsoleLayout layout(config().insole(session.size), config().sensor);
  for (auto _ : state) {
    std::vector<gaitmon::Step> steps;
    gaitmon::segment_session(csv, config(),
                             [&](gaitmon::Step&& s) { steps.push_back(std::move(s)); });
    const auto input =
        gaitmon::prepare_discrepancy_input(steps, layout, config(), gaitmon::AnalysisSettings{});
    benchmark::DoNotOptimize(gaitmon::find_discrepancy(input));
  }
}

void BM_Discrepancy60sNone(benchmark::State& state) {
  run(state, {"none", {}});
}
void BM_Discrepancy60sImpact(benchmark::State& state) {
  run(state, {"impact_transient", {}});
}
// Saturation is the one candidate that is not affine in the force: once it is named (here, an
// 85-bit ceiling on size 41-42), every candidate of the search for a second effect is refined
// by Gauss-Newton.
void BM_Discrepancy60sSaturation(benchmark::State& state) {
  run(state, {"sensor_saturation", {{"ceiling_bits", 85.0}}, gaitmon::InsoleSize::S41_42, 7});
}

}  // namespace

BENCHMARK(BM_Discrepancy60sNone)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK(BM_Discrepancy60sImpact)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK(BM_Discrepancy60sSaturation)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK_MAIN();
