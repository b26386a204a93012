// A 10-minute two-foot session replayed through the monitor as fast as it goes (a replay waits
// for room rather than dropping): every thread busy at once (run under TSan in CI), and every
// frame and step accounted for.
#include <gtest/gtest.h>

#include <atomic>
#include <map>

#include "gaitmon/monitor.hpp"
#include "gaitmon/session.hpp"
#include "gaitmon/simulator.hpp"
#include "monitor_support.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

// Counts the per-frame reports instead of keeping them (120 000 of them would be ~80 MB).
class CountingPublisher : public test::RecordingPublisher {
 public:
  using RecordingPublisher::publish;
  void publish(const FrameReport&) override { frames_.fetch_add(1); }
  std::uint64_t frame_reports() const { return frames_.load(); }

 private:
  std::atomic<std::uint64_t> frames_{0};
};

TEST(MonitorSoak, TenMinuteSessionAtMaxSpeedAccountsForEveryFrameAndStep) {
  const Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  const auto dir = test::scratch_dir("monitor-soak");
  SimulationOptions simulation;
  simulation.duration_s = 600.0;
  simulation.seed = 11;
  simulate_session(config, simulation, dir / "ten.csv", dir / "ten.truth.json");

  CountingPublisher publisher;
  MonitorOptions options;
  // Short fits: the point is many fits racing through the workers, not their values.
  options.analysis.fit.starts = 1;
  options.analysis.fit.max_iterations = 5;
  options.backlog_overflow = BacklogOverflow::Wait;
  Monitor monitor(config, options, publisher);
  SessionReader reader(dir / "ten.csv");
  Frame frame;
  std::uint32_t sequence[2] = {0, 0};
  std::uint64_t offered = 0;
  while (reader.next(frame)) {
    const auto foot = static_cast<std::size_t>(frame.foot);
    ++offered;
    ASSERT_TRUE(monitor.offer_wait(
        test::sensor_frame(frame, reader.header().insole_size, sequence[foot]++)));
  }
  monitor.stop();

  ASSERT_EQ(offered, 2u * 60000u);
  const MonitorCounters c = monitor.counters();
  EXPECT_EQ(c.frames_offered, offered);
  EXPECT_EQ(c.ring_drops, 0u);
  EXPECT_EQ(c.frames_processed + c.ring_drops, offered);
  EXPECT_EQ(c.frames_rejected, 0u);
  EXPECT_GT(c.steps_queued, 900u) << "about 1000 steps in 10 minutes";
  EXPECT_EQ(c.step_drops, 0u);
  EXPECT_EQ(c.fits_published, c.steps_queued);
  EXPECT_EQ(c.step_backlog, 0u);
  EXPECT_EQ(c.ring_depth, 0u);

  std::map<Foot, int> last{{Foot::Left, -1}, {Foot::Right, -1}};
  for (const FitReport& fit : publisher.fits()) {
    EXPECT_GT(fit.step, last[fit.foot]) << "fits out of step order";
    last[fit.foot] = fit.step;
  }
  EXPECT_EQ(publisher.fits().size(), c.fits_published);
  EXPECT_EQ(publisher.frame_reports(), c.frames_processed);
  const StatusReport final_status = publisher.statuses().back();
  EXPECT_EQ(final_status.connection, "finished");
  EXPECT_EQ(final_status.frames_processed, c.frames_processed);
  EXPECT_EQ(final_status.ring_drops, c.ring_drops);
  EXPECT_EQ(final_status.step_drops, c.step_drops);
  EXPECT_EQ(final_status.fits_published, c.fits_published);
}

}  // namespace
}  // namespace gaitmon
