// Benchmarks of the session CSV reader (a synthetic ~40 MB recording at size 45-46) and writer,
// and of the creep correction every frame read goes through under [sensor_creep].
#include <benchmark/benchmark.h>

#include <cstdint>
#include <filesystem>
#include <random>
#include <vector>

#include "gaitmon/creep.hpp"
#include "gaitmon/session.hpp"
#include "test_support.hpp"

namespace {

namespace fs = std::filesystem;
using gaitmon::Foot;
using gaitmon::Frame;

constexpr std::size_t kSensors = 161;
// 100 Hz per foot for about 7.5 minutes: about 40 MB of text.
constexpr std::size_t kFramesPerFoot = 45000;

const fs::path& bench_dir() {
  static const fs::path dir = gaitmon::test::scratch_dir("session_bench");
  return dir;
}

gaitmon::SessionHeader bench_header() {
  gaitmon::SessionHeader h;
  h.insole_size = gaitmon::InsoleSize::S45_46;
  h.sensors = kSensors;
  h.subject = "synthetic";
  return h;
}

// Mostly unloaded or lightly loaded cells (one digit), a third moderately loaded (two digits) and a
// few under the heel or forefoot peak (three digits), in no predictable order.
void fill_bits(std::mt19937& rng, std::vector<std::uint8_t>& bits) {
  std::uniform_int_distribution<int> kind(0, 99);
  std::uniform_int_distribution<int> one(0, 9);
  std::uniform_int_distribution<int> two(10, 99);
  std::uniform_int_distribution<int> three(100, 255);
  for (auto& b : bits) {
    const int k = kind(rng);
    b = static_cast<std::uint8_t>(k < 60 ? one(rng) : k < 92 ? two(rng) : three(rng));
  }
}

std::vector<Frame> synthetic_frames(std::size_t per_foot) {
  std::mt19937 rng(12345);
  std::vector<Frame> frames;
  frames.reserve(2 * per_foot);
  for (std::size_t i = 0; i < per_foot; ++i) {
    for (Foot foot : gaitmon::kFeet) {
      Frame f{static_cast<double>(i) / 100.0 + (foot == Foot::Right ? 0.004 : 0.0), foot,
              std::vector<std::uint8_t>(kSensors)};
      fill_bits(rng, f.bits);
      frames.push_back(std::move(f));
    }
  }
  return frames;
}

const fs::path& session_file() {
  static const fs::path path = [] {
    const fs::path file = bench_dir() / "synthetic.csv";
    gaitmon::SessionWriter writer(file, bench_header());
    std::mt19937 rng(2024);
    Frame f{0.0, Foot::Left, std::vector<std::uint8_t>(kSensors)};
    for (std::size_t i = 0; i < kFramesPerFoot; ++i) {
      for (Foot foot : gaitmon::kFeet) {
        f.t_s = static_cast<double>(i) / 100.0 + (foot == Foot::Right ? 0.004 : 0.0);
        f.foot = foot;
        fill_bits(rng, f.bits);
        writer.write(f);
      }
    }
    writer.close();
    return file;
  }();
  return path;
}

void BM_ReadSession(benchmark::State& state) {
  const fs::path& path = session_file();
  const auto bytes = static_cast<std::int64_t>(fs::file_size(path));
  std::size_t frames = 0;
  for (auto _ : state) {
    gaitmon::SessionReader reader(path);
    Frame frame;
    std::size_t n = 0;
    while (reader.next(frame)) ++n;
    benchmark::DoNotOptimize(frame.bits.data());
    frames = n;
  }
  state.SetBytesProcessed(state.iterations() * bytes);
  state.counters["file_MB"] = static_cast<double>(bytes) / 1e6;
  state.counters["frames"] = static_cast<double>(frames);
}
BENCHMARK(BM_ReadSession)->Unit(benchmark::kMillisecond);

void BM_WriteSession(benchmark::State& state) {
  const std::vector<Frame> frames = synthetic_frames(5000);
  const fs::path path = bench_dir() / "written.csv";
  for (auto _ : state) {
    gaitmon::SessionWriter writer(path, bench_header());
    for (const Frame& f : frames) writer.write(f);
    writer.close();
  }
  state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(fs::file_size(path)));
  state.counters["frames"] = static_cast<double>(frames.size());
}
BENCHMARK(BM_WriteSession)->Unit(benchmark::kMillisecond);

// One frame of 161 cells undone, as segment_session and the live monitor's detector do to each
// frame under a [sensor_creep] of gain 0.3 and tau 1 s.
void BM_UndoCreepPerFrame(benchmark::State& state) {
  const std::vector<Frame> frames = synthetic_frames(5000);
  std::vector<Frame> work = frames;
  std::size_t done = 0;
  for (auto _ : state) {
    gaitmon::CreepCorrection creep(0.3, 1.0);
    state.PauseTiming();
    work = frames;
    state.ResumeTiming();
    for (Frame& f : work) creep.undo(f);
    benchmark::DoNotOptimize(work.back().bits.data());
    done += work.size();
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(done));
  // A rate of frames per microsecond, inverted: microseconds per frame.
  state.counters["us_per_frame"] = benchmark::Counter(
      static_cast<double>(done) / 1e6, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_UndoCreepPerFrame)->Unit(benchmark::kMillisecond);

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  fs::remove_all(bench_dir());
  return 0;
}
