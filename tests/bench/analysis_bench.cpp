// The per-step analysis of one foot-step (warm ellipse cache, 8 region fits; target 2 ms), on
// the centre raster with the footprint and on the coverage raster with footprint-mean,
// `gaitmon analyze` on a 10-minute two-foot simulated session of each raster (target 3 s), and
// the live monitor's pools of every region over its window of steps (GAITMON_TISSUE, at most ten
// a second).
#include <benchmark/benchmark.h>

#include <array>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "gaitmon/analysis.hpp"
#include "gaitmon/batch.hpp"
#include "gaitmon/pooling.hpp"
#include "gaitmon/simulator.hpp"
#include "test_support.hpp"

namespace {

namespace fs = std::filesystem;

const fs::path& bench_dir() {
  static const fs::path dir = gaitmon::test::scratch_dir("analysis_bench");
  return dir;
}

const gaitmon::Config& config() {
  static const gaitmon::Config c = gaitmon::load_config(gaitmon::default_config_path());
  return c;
}

fs::path simulated(double duration_s,
                   gaitmon::Rasterisation raster = gaitmon::Rasterisation::CellCentre) {
  const fs::path csv = bench_dir() / ("walk-" + std::to_string(static_cast<int>(duration_s)) + "-" +
                                      std::string(gaitmon::rasterisation_name(raster)) + ".csv");
  if (!fs::exists(csv)) {
    gaitmon::SimulationOptions options;
    options.size = gaitmon::InsoleSize::S37_38;
    options.duration_s = duration_s;
    options.seed = 7;
    options.rasterisation = raster;
    gaitmon::simulate_session(config(), options, csv, fs::path(csv).replace_extension(".json"));
  }
  return csv;
}

void BM_AnalyseStep(benchmark::State& state, gaitmon::Rasterisation raster,
                    gaitmon::AreaSource area) {
  std::vector<gaitmon::Step> steps;
  gaitmon::segment_session(simulated(30.0, raster), config(), [&](gaitmon::Step&& step) {
    if (step.status == gaitmon::StepStatus::Ok) steps.push_back(std::move(step));
  });
  const gaitmon::InsoleLayout layout(config().insole(gaitmon::InsoleSize::S37_38), config().sensor);
  gaitmon::AnalysisSettings settings;
  settings.area = area;
  gaitmon::ContactEllipseCache cache;
  for (const auto& step : steps) gaitmon::analyse_step(step, layout, config(), settings, &cache);
  std::size_t i = 0;
  for (auto _ : state) {
    auto a = gaitmon::analyse_step(steps[i], layout, config(), settings, &cache);
    benchmark::DoNotOptimize(a.nrmse_total_pct);
    i = (i + 1) % steps.size();
  }
  state.counters["steps_cycled"] = static_cast<double>(steps.size());
}
BENCHMARK_CAPTURE(BM_AnalyseStep, centre_raster_footprint, gaitmon::Rasterisation::CellCentre,
                  gaitmon::AreaSource::Footprint)
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(5);
BENCHMARK_CAPTURE(BM_AnalyseStep, coverage_raster_footprint_mean, gaitmon::Rasterisation::Coverage,
                  gaitmon::AreaSource::FootprintMean)
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(5);

// What the monitor's tissue thread does for one report: every region's steps pooled over a full
// window ([monitor] tissue_window_steps of the 10-minute walk's steps, both feet).
void BM_PoolEveryRegionOverTheTissueWindow(benchmark::State& state) {
  const gaitmon::InsoleLayout layout(config().insole(gaitmon::InsoleSize::S37_38), config().sensor);
  gaitmon::ContactEllipseCache cache;
  std::vector<gaitmon::StepAnalysis> window;
  const auto capacity = static_cast<std::size_t>(config().monitor.tissue_window_steps);
  gaitmon::segment_session(simulated(600.0), config(), [&](gaitmon::Step&& step) {
    if (step.status == gaitmon::StepStatus::Ok && window.size() < capacity)
      window.push_back(gaitmon::analyse_step(step, layout, config(), {}, &cache));
  });
  std::array<std::vector<gaitmon::MaterialEstimate>, gaitmon::kRegionCount> estimates;
  for (const gaitmon::StepAnalysis& step : window) {
    for (std::size_t i = 0; i < gaitmon::kRegionCount; ++i) {
      if (const auto e = gaitmon::material_estimate(step.regions[i].fit))
        estimates[i].push_back(*e);
    }
  }
  int pooled = 0;
  for (auto _ : state) {
    pooled = 0;
    for (std::size_t i = 0; i < gaitmon::kRegionCount; ++i) {
      const gaitmon::PooledEstimates p = gaitmon::pool_region_steps(
          estimates[i], gaitmon::kRegions[i], config().pooling, config().fit_bounds);
      pooled += p.pooled ? 1 : 0;
      benchmark::DoNotOptimize(p.mean);
    }
  }
  state.counters["steps"] = static_cast<double>(window.size());
  state.counters["regions_pooled"] = pooled;
}
BENCHMARK(BM_PoolEveryRegionOverTheTissueWindow)->Unit(benchmark::kMillisecond)->Repetitions(5);

/// The gaitmon executable of the same build: tests/ sits beside it.
fs::path gaitmon_executable() {
  return fs::read_symlink("/proc/self/exe").parent_path().parent_path() / "gaitmon";
}

// `flags`: an option of `analyze` to compare with the default (none), after a space. On the
// coverage raster the default (--area auto) takes footprint-mean.
void BM_AnalyzeCommandTenMinutes(benchmark::State& state, gaitmon::Rasterisation raster,
                                 const char* flags) {
  const fs::path exe = gaitmon_executable();
  if (!fs::exists(exe)) {
    state.SkipWithError("the gaitmon executable is not built beside tests/");
    return;
  }
  const std::string command = exe.string() + " analyze " + simulated(600.0, raster).string() +
                              " --out " + (bench_dir() / "out").string() + flags + " > /dev/null";
  for (auto _ : state) {
    if (std::system(command.c_str()) != 0) {
      state.SkipWithError("gaitmon analyze failed");
      return;
    }
  }
}
BENCHMARK_CAPTURE(BM_AnalyzeCommandTenMinutes, default, gaitmon::Rasterisation::CellCentre, "")
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->Repetitions(3)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_AnalyzeCommandTenMinutes, coverage_raster_default,
                  gaitmon::Rasterisation::Coverage, "")
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->Repetitions(3)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_AnalyzeCommandTenMinutes, m_per_session, gaitmon::Rasterisation::CellCentre,
                  " --m-per-session")
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->Repetitions(3)
    ->UseRealTime();

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  fs::remove_all(bench_dir());
  return 0;
}
