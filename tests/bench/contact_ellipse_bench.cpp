// Time per contact-ellipse call: a Case 3 heel, a Case 3 forefoot with offset rows, a rectangle,
// and a Case 3 heel answered by the pattern cache.
#include <benchmark/benchmark.h>

#include <string>
#include <vector>

#include "gaitmon/contact_ellipse.hpp"

namespace {

using gaitmon::ActiveCell;

/// Cells from a picture, most anterior row first; '>' shifts a row half a cell.
std::vector<ActiveCell> cells_of(const std::vector<std::string>& rows) {
  std::vector<ActiveCell> cells;
  const auto n = static_cast<int>(rows.size());
  for (int r = 0; r < n; ++r) {
    std::string row = rows[static_cast<std::size_t>(r)];
    double offset = 0.0;
    if (!row.empty() && row.front() == '>') {
      offset = 0.5;
      row.erase(0, 1);
    }
    for (std::size_t i = 0; i < row.size(); ++i) {
      if (row[i] == '#') {
        cells.push_back({(static_cast<double>(i) + offset) * 7.5, (n - 1 - r) * 15.0, false});
      }
    }
  }
  return cells;
}

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
