// Time per contact-ellipse call: a Case 3 heel, a Case 3 forefoot with offset rows, a rectangle,
// and a Case 3 heel answered by the pattern cache.
#include <benchmark/benchmark.h>

#include <string>
#include <vector>

#include "gaitmon/contact_ellipse.hpp"
#include "test_support.hpp"

namespace {

using gaitmon::ActiveCell;
using gaitmon::test::cells_of;

const std::vector<ActiveCell> kHeel21 = cells_of({".###.", "#####", "#####", "#####", ".###."});
const std::vector<ActiveCell> kForefoot14 = cells_of({">###", "####", ">###", "####"});
const std::vector<ActiveCell> kRectangle12 = cells_of({"####", "####", "####"});

void run(benchmark::State& state, const std::vector<ActiveCell>& cells) {
  for (auto _ : state) {
    auto e = gaitmon::fit_contact_ellipse(cells, {}, gaitmon::Region::Heel, false);
    benchmark::DoNotOptimize(e);
  }
}

void BM_Case3Heel21(benchmark::State& state) {
  run(state, kHeel21);
}
void BM_Case3Forefoot14(benchmark::State& state) {
  run(state, kForefoot14);
}
void BM_Rectangle12(benchmark::State& state) {
  run(state, kRectangle12);
}

void BM_Case3Heel21Cached(benchmark::State& state) {
  gaitmon::ContactEllipseCache cache;
  for (auto _ : state) {
    auto e = cache.fit(kHeel21, {}, gaitmon::Region::Heel, false);
    benchmark::DoNotOptimize(e);
  }
}

BENCHMARK(BM_Case3Heel21)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_Case3Forefoot14)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_Rectangle12)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_Case3Heel21Cached)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
