// The discrepancy workflow on a 60-second two-foot simulated session (target: 60 s): the
// segmentation, the per-step fits and the candidate search, as `gaitmon discrepancy` runs them,
// on sessions with a hidden effect (so a second effect is searched for too) and without one.
#include <benchmark/benchmark.h>

#include <filesystem>
#include <string>
#include <vector>

#include "gaitmon/batch.hpp"
#include "gaitmon/discrepancy.hpp"
#include "gaitmon/simulator.hpp"
#include "test_support.hpp"

namespace {

namespace fs = std::filesystem;

const gaitmon::Config& config() {
  static const gaitmon::Config c = gaitmon::load_config(gaitmon::default_config_path());
  return c;
}

fs::path simulated(const std::string& effect) {
  static const fs::path dir = gaitmon::test::scratch_dir("discrepancy_bench");
  const fs::path csv = dir / (effect + "-60.csv");
  if (!fs::exists(csv)) {
    gaitmon::SimulationOptions options;
    options.duration_s = 60.0;
    options.seed = 3;
    if (effect != "none") options.effects = {effect};
    gaitmon::simulate_session(config(), options, csv, fs::path(csv).replace_extension(".json"));
  }
  return csv;
}

void run(benchmark::State& state, const std::string& effect) {
  const fs::path csv = simulated(effect);
  const gaitmon::InsoleLayout layout(config().insole(gaitmon::InsoleSize::S37_38), config().sensor);
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
  run(state, "none");
}
void BM_Discrepancy60sImpact(benchmark::State& state) {
  run(state, "impact_transient");
}
// Saturation is the one candidate that is not affine in the force: once it is named, every
// candidate of the search for a second effect is refined by Gauss-Newton.
void BM_Discrepancy60sSaturation(benchmark::State& state) {
  run(state, "sensor_saturation");
}

}  // namespace

BENCHMARK(BM_Discrepancy60sNone)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK(BM_Discrepancy60sImpact)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK(BM_Discrepancy60sSaturation)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();
BENCHMARK_MAIN();
