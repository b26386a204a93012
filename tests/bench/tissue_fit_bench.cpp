// Time of fit_region on simulated data: one region-step (the heel, about 50 frames) and the
// eight region fits of one foot-step (the target is 2 ms per foot-step, ellipses included).
#include <benchmark/benchmark.h>

#include <array>
#include <optional>
#include <vector>

#include "gaitmon/batch.hpp"
#include "gaitmon/config.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/simulator.hpp"
#include "gaitmon/stance.hpp"
#include "gaitmon/tissue_fit.hpp"
#include "test_support.hpp"

namespace {

using namespace gaitmon;

struct FootStep {
  Config config;
  std::array<RegionSeries, kRegionCount> series;
  std::array<EllipsoidParams, kRegionCount> truth;
};

// The first whole step of a 6 s simulated session of size 37-38.
const FootStep& foot_step() {
  static const FootStep data = [] {
    FootStep fs;
    fs.config = load_config(test::source_dir() / "config" / "gaitmon.toml");
    const auto dir = test::scratch_dir("tissue-fit-bench");
    SimulationOptions options;
    options.duration_s = 6.0;
    const SimulationTruth truth =
        simulate_session(fs.config, options, dir / "session.csv", dir / "truth.json");
    const InsoleLayout layout(fs.config.insole(options.size), fs.config.sensor);
    std::optional<StanceSeries> stance;
    segment_session(dir / "session.csv", fs.config, [&](Step&& step) {
      if (!stance && step.status == StepStatus::Ok) {
        stance = measure_stance(step, layout, fs.config.calibration);
      }
    });
    for (Region region : kRegions) {
      RegionSeries& s = fs.series[index_of(region)];
      for (std::size_t f = 0; f < stance->size(); ++f) {
        s.t_s.push_back(stance->t_s[f]);
        s.area_mm2.push_back(stance->at(f, region).ellipse.area_mm2);
        s.force_n.push_back(stance->at(f, region).force_n);
      }
      fs.truth[index_of(region)] = truth.regions[index_of(region)].params;
    }
    return fs;
  }();
  return data;
}

void BM_FitHeelRegionStep(benchmark::State& state) {
  const FootStep& fs = foot_step();
  FitSettings settings;
  for (auto _ : state) {
    RegionFit fit = fit_region(fs.series[0], fs.truth[0], fs.config.fit_bounds, settings);
    benchmark::DoNotOptimize(fit);
  }
  state.counters["frames"] = static_cast<double>(fs.series[0].t_s.size());
}
BENCHMARK(BM_FitHeelRegionStep)->Unit(benchmark::kMillisecond);

void BM_FitFootStepEightRegions(benchmark::State& state) {
  const FootStep& fs = foot_step();
  FitSettings settings;
  for (auto _ : state) {
    for (std::size_t r = 0; r < kRegionCount; ++r) {
      RegionFit fit = fit_region(fs.series[r], fs.truth[r], fs.config.fit_bounds, settings);
      benchmark::DoNotOptimize(fit);
    }
  }
}
BENCHMARK(BM_FitFootStepEightRegions)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
