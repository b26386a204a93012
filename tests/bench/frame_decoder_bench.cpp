// Frame decoder throughput (target >= 200 MB/s) on a clean stream and on one with link faults,
// fed in reads of 4 KiB (the serial driver's buffer) and 64 KiB (the fake driver's batches).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdint>
#include <vector>

#include "drivers/frame_decoder.hpp"
#include "gaitmon/session.hpp"
#include "replay/fault_injector.hpp"

namespace {

using gaitmon::Foot;
using gaitmon::InsoleSize;
using gaitmon::SensorFrame;
using gaitmon::drivers::FrameDecoder;
using gaitmon::drivers::WireFormat;

// About 12 MB: 100000 frames of size 37-38 (123 bytes each), both feet.
std::vector<std::uint8_t> make_stream(bool faults) {
  const WireFormat format;
  gaitmon::replay::FaultOptions options;
  if (faults) {
    options.garbage_rate = 0.02;
    options.crc_rate = 0.01;
    options.truncate_rate = 0.01;
  }
  gaitmon::replay::FaultInjector injector(options, format);
  std::vector<std::uint8_t> stream;
  std::vector<std::uint8_t> wire(format.frame_bytes(107));
  SensorFrame frame;
  frame.size = InsoleSize::S37_38;
  frame.sensor_count = 107;
  for (std::uint32_t i = 0; i < 100000; ++i) {
    frame.foot = i % 2 == 0 ? Foot::Left : Foot::Right;
    frame.sequence = i / 2;
    frame.device_time_us = i * 5000;
    for (std::size_t s = 0; s < 107; ++s) frame.bits[s] = static_cast<std::uint8_t>(s * 3 + i);
    gaitmon::drivers::encode_frame(format, frame, wire);
    injector.append(wire, frame.foot, frame.sequence, stream);
  }
  return stream;
}

void decode(benchmark::State& state, bool faults) {
  const std::vector<std::uint8_t> stream = make_stream(faults);
  const auto chunk = static_cast<std::size_t>(state.range(0));
  std::uint64_t frames = 0;
  for (auto _ : state) {
    FrameDecoder decoder;
    for (std::size_t at = 0; at < stream.size(); at += chunk) {
      decoder.feed(std::span(stream).subspan(at, std::min(chunk, stream.size() - at)),
                   [&](const SensorFrame& f) {
                     ++frames;
                     benchmark::DoNotOptimize(f.bits[0]);
                   });
    }
    benchmark::DoNotOptimize(frames);
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * stream.size()));
  state.counters["frames_per_s"] =
      benchmark::Counter(static_cast<double>(frames), benchmark::Counter::kIsRate);
}

void BM_DecodeClean(benchmark::State& state) {
  decode(state, false);
}
void BM_DecodeWithFaults(benchmark::State& state) {
  decode(state, true);
}

BENCHMARK(BM_DecodeClean)->Arg(4096)->Arg(65536)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DecodeWithFaults)->Arg(4096)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
