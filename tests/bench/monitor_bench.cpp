// The live monitor's speed: the frame ring between two threads (target >= 10 M frames/s), a
// 10-minute two-foot session replayed through the monitor as fast as it goes, with fitting
// (target >= 300 x real time), the end-of-step to publication latency when frames arrive at
// real time (target p99 <= 20 ms), and how long shutdown takes (target 2 s).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "gaitmon/frame_ring.hpp"
#include "gaitmon/monitor.hpp"
#include "gaitmon/simulator.hpp"
#include "monitor_support.hpp"
#include "test_support.hpp"

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

const gaitmon::Config& config() {
  static const gaitmon::Config c = gaitmon::load_config(gaitmon::default_config_path());
  return c;
}

std::vector<gaitmon::SensorFrame> ten_minute_session() {
  const fs::path dir = gaitmon::test::scratch_dir("monitor_bench");
  gaitmon::SimulationOptions options;
  options.duration_s = 600.0;
  options.seed = 7;
  gaitmon::simulate_session(config(), options, dir / "ten.csv", dir / "ten.truth.json");
  return gaitmon::test::session_frames(dir / "ten.csv");
}

/// Keeps only what the benchmarks report: the fits' latencies, and those of the fits with
/// effects inside.
class LatencyPublisher : public gaitmon::Publisher {
 public:
  void publish(const gaitmon::FrameReport&) override {}
  void publish(const gaitmon::StepEvent&) override {}
  void publish(const gaitmon::StatusReport&) override {}
  void publish(const gaitmon::RawFrameReport&) override {}
  void publish(const gaitmon::EffectsReport&) override {}
  void publish(const gaitmon::TissueReport&) override {}
  void publish(const gaitmon::FitReport& r) override {
    const std::lock_guard lock(mutex_);
    latencies_ms_.push_back(r.latency_ms);
    if (!r.effects_inside.empty()) inside_ms_.push_back(r.latency_ms);
  }
  std::vector<double> latencies_ms() const {
    const std::lock_guard lock(mutex_);
    return latencies_ms_;
  }
  std::vector<double> inside_ms() const {
    const std::lock_guard lock(mutex_);
    return inside_ms_;
  }

 private:
  mutable std::mutex mutex_;
  std::vector<double> latencies_ms_;
  std::vector<double> inside_ms_;
};

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(v.size())));
  return v[std::max<std::size_t>(rank, 1) - 1];
}

// Waiting for the other thread: spin a little, doubling each round (it usually runs on the other
// core and is about to move), then give the core away (on a shared machine it may be waiting
// for this one).
class Backoff {
 public:
  void pause() {
    if (rounds_ < kRounds) {
      for (int i = 0; i < 1 << rounds_; ++i) {
#if defined(__x86_64__) || defined(__i386__)
        __builtin_ia32_pause();
#endif
      }
      ++rounds_;
    } else {
      std::this_thread::yield();
    }
  }
  void reset() {
    rounds_ = 0;
  }

 private:
  static constexpr int kRounds = 8;
  int rounds_ = 0;
};

// A producer thread pushing frames one at a time, as a driver does, and a consumer thread taking
// them in batches of up to range(1), as the monitor's detector does. Every frame really crosses
// between the threads, and the consumer checks that each arrives once and in order.
void BM_FrameRingThroughput(benchmark::State& state) {
  constexpr std::uint64_t kFrames = 4'000'000;
  gaitmon::FrameRing ring(static_cast<std::size_t>(state.range(0)));
  const auto batch = static_cast<std::size_t>(state.range(1));
  gaitmon::SensorFrame frame;
  frame.sensor_count = 107;
  std::uint64_t out_of_order = 0;
  for (auto _ : state) {
    std::thread consumer([&] {
      std::vector<gaitmon::SensorFrame> out(batch);
      Backoff empty;
      for (std::uint64_t next = 0; next < kFrames;) {
        const std::size_t n = ring.try_pop_batch(out);
        if (n == 0) {
          empty.pause();
          continue;
        }
        empty.reset();
        for (std::size_t i = 0; i < n; ++i, ++next) {
          out_of_order += out[i].sequence != static_cast<std::uint32_t>(next);
        }
      }
    });
    Backoff full;
    for (std::uint64_t i = 0; i < kFrames; ++i) {
      frame.sequence = static_cast<std::uint32_t>(i);
      while (!ring.try_push(frame)) full.pause();
      full.reset();
    }
    consumer.join();
  }
  if (out_of_order != 0) state.SkipWithError("frames arrived out of order");
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * kFrames));
}
BENCHMARK(BM_FrameRingThroughput)
    ->ArgNames({"capacity", "batch"})
    ->Args({4096, 64})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

// The ring's own cost without scheduling: one thread pushes a batch and pops it again. On a
// loaded machine the two-thread figure above measures the scheduler as much as the ring.
void BM_FrameRingPushPopOneThread(benchmark::State& state) {
  const auto batch = static_cast<std::size_t>(state.range(0));
  gaitmon::FrameRing ring(batch);
  gaitmon::SensorFrame frame;
  frame.sensor_count = 107;
  gaitmon::SensorFrame out;
  for (auto _ : state) {
    for (std::size_t i = 0; i < batch; ++i) {
      frame.sequence = static_cast<std::uint32_t>(i);
      benchmark::DoNotOptimize(ring.try_push(frame));
    }
    for (std::size_t i = 0; i < batch; ++i) benchmark::DoNotOptimize(ring.try_pop(out));
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * batch));
}
BENCHMARK(BM_FrameRingPushPopOneThread)->Arg(256);

// The replay path without the wire: frames offered with offer_wait, steps waiting for a worker
// rather than dropped, full fits, frame reports on. Reports the speed as a multiple of the 600 s.
void BM_MonitorReplayTenMinutes(benchmark::State& state) {
  static const std::vector<gaitmon::SensorFrame> frames = ten_minute_session();
  gaitmon::Config c = config();
  c.monitor.publish_frames = state.range(0) != 0;
  double seconds = 0.0;
  for (auto _ : state) {
    LatencyPublisher publisher;
    gaitmon::MonitorOptions options;
    options.backlog_overflow = gaitmon::BacklogOverflow::Wait;
    const auto start = Clock::now();
    gaitmon::Monitor monitor(c, options, publisher);
    for (const auto& frame : frames) {
      if (!monitor.offer_wait(frame)) state.SkipWithError("the monitor refused a frame");
    }
    monitor.stop();
    seconds += std::chrono::duration<double>(Clock::now() - start).count();
    state.counters["fits"] = static_cast<double>(monitor.counters().fits_published);
  }
  state.counters["x_real_time"] = 600.0 * static_cast<double>(state.iterations()) / seconds;
}
BENCHMARK(BM_MonitorReplayTenMinutes)
    ->ArgName("publish_frames")
    ->Arg(1)
    ->Arg(0)
    ->Iterations(1)
    ->UseRealTime()
    ->Unit(benchmark::kSecond);

// Frames of the bundled 60 s demo offered at their own pace (as a live insole delivers them);
// the latency of each fit from the step's finalisation to its publication. With effects
// (stress_relaxation), each step after the first estimate is fitted with it inside.
void BM_MonitorLatencyRealTime(benchmark::State& state) {
  static const std::vector<gaitmon::SensorFrame> frames =
      gaitmon::test::session_frames(gaitmon::test::demo_session());
  gaitmon::Config with = config();
  if (state.range(0) != 0) with.model.effects = {"stress_relaxation"};
  std::vector<double> latencies;
  std::vector<double> inside;
  for (auto _ : state) {
    LatencyPublisher publisher;
    gaitmon::Monitor monitor(with, gaitmon::MonitorOptions{}, publisher);
    const auto start = Clock::now();
    const std::uint32_t t0 = frames.front().device_time_us;
    for (const auto& frame : frames) {
      std::this_thread::sleep_until(start + std::chrono::microseconds(frame.device_time_us - t0));
      if (!monitor.offer(frame)) state.SkipWithError("a frame was dropped at real time");
    }
    monitor.stop();
    const auto l = publisher.latencies_ms();
    latencies.insert(latencies.end(), l.begin(), l.end());
    const auto in = publisher.inside_ms();
    inside.insert(inside.end(), in.begin(), in.end());
  }
  state.counters["fits"] = static_cast<double>(latencies.size());
  state.counters["p50_ms"] = percentile(latencies, 0.50);
  state.counters["p99_ms"] = percentile(latencies, 0.99);
  state.counters["max_ms"] = percentile(latencies, 1.0);
  if (state.range(0) != 0) {
    state.counters["inside_fits"] = static_cast<double>(inside.size());
    state.counters["inside_p50_ms"] = percentile(inside, 0.50);
    state.counters["inside_p99_ms"] = percentile(inside, 0.99);
  }
}
BENCHMARK(BM_MonitorLatencyRealTime)
    ->ArgName("effects")
    ->Arg(0)
    ->Arg(1)
    ->Iterations(1)
    ->UseRealTime()
    ->Unit(benchmark::kSecond);

// How long shutdown takes once the driver has stopped: the 60 s demo offered as fast as the
// monitor takes it, with [model] effects = stress_relaxation, then stop() timed from the call to
// its return. range(0) = 0: a plain stop, which fits and publishes every step still queued and
// fits the effects' window as it ends; 1: an interrupted run (close() first, as on SIGINT or
// SIGTERM), which keeps the effects' latest estimate (the target is 2 s).
void BM_MonitorShutdown(benchmark::State& state) {
  static const std::vector<gaitmon::SensorFrame> frames =
      gaitmon::test::session_frames(gaitmon::test::demo_session());
  gaitmon::Config c = config();
  c.model.effects = {"stress_relaxation"};
  const bool interrupted = state.range(0) != 0;
  for (auto _ : state) {
    LatencyPublisher publisher;
    gaitmon::MonitorOptions options;
    options.backlog_overflow = gaitmon::BacklogOverflow::Wait;
    gaitmon::Monitor monitor(c, options, publisher);
    for (const auto& frame : frames) {
      if (!monitor.offer_wait(frame)) state.SkipWithError("the monitor refused a frame");
    }
    const auto start = Clock::now();
    if (interrupted) monitor.close();
    monitor.stop();
    state.SetIterationTime(std::chrono::duration<double>(Clock::now() - start).count());
    state.counters["fits"] = static_cast<double>(monitor.counters().fits_published);
  }
}
BENCHMARK(BM_MonitorShutdown)
    ->ArgName("interrupted")
    ->Arg(0)
    ->Arg(1)
    ->Iterations(3)
    ->UseManualTime()
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
