// LcmPublisher's cost per message over memq://: with a subscriber (encode, queue, dispatch to a
// raw handler) and without one (encode and hand over; memq drops a message nobody subscribes to).
#include <benchmark/benchmark.h>

#include <lcm/lcm-cpp.hpp>
#include <memory>

#include "gaitmon/lcm_connection.hpp"
#include "gaitmon/lcm_publisher.hpp"
#include "lcm/sample_reports.hpp"

namespace gaitmon {
namespace {

LcmSettings memq_settings() {
  LcmSettings settings;
  settings.url = "memq://";
  return settings;
}

void count_message(const lcm::ReceiveBuffer*, const std::string&, std::int64_t* received) {
  ++*received;
}

template <typename Report>
void publish_received(benchmark::State& state, const Report& report, const char* channel) {
  const auto bus = open_lcm("memq://");
  std::int64_t received = 0;
  bus->subscribeFunction(channel, &count_message, &received);
  LcmPublisher publisher(bus, memq_settings());
  for (auto _ : state) {
    publisher.publish(report);
    bus->handleTimeout(0);
  }
  if (received != static_cast<std::int64_t>(state.iterations())) {
    state.SkipWithError("messages were lost");
  }
  state.SetItemsProcessed(state.iterations());
}

void BM_FrameReportPublishedAndReceived(benchmark::State& state) {
  publish_received(state, test::sample_frame(), "GAITMON_FRAME");
}
BENCHMARK(BM_FrameReportPublishedAndReceived);

void BM_FitReportPublishedAndReceived(benchmark::State& state) {
  publish_received(state, test::sample_fit(), "GAITMON_FIT");
}
BENCHMARK(BM_FitReportPublishedAndReceived);

// Several threads share one publisher, as the detector and the fit workers do.
void BM_FrameReportPublishedNoSubscriber(benchmark::State& state) {
  // Made by thread 0 before the loop's start barrier, dropped after its end barrier.
  static std::unique_ptr<LcmPublisher> publisher;
  if (state.thread_index() == 0) publisher = std::make_unique<LcmPublisher>(memq_settings());
  const FrameReport report = test::sample_frame();
  for (auto _ : state) publisher->publish(report);
  if (state.thread_index() == 0) {
    if (publisher->failed_publishes() != 0) state.SkipWithError("publishes failed");
    publisher.reset();
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_FrameReportPublishedNoSubscriber)->Threads(1)->Threads(2);

}  // namespace
}  // namespace gaitmon

BENCHMARK_MAIN();
