// The pacer's schedule: the first frame sets the origin, a frame is due (t - t_first) / speed
// after it, late frames are due at once, and stop ends a wait. The exact schedule and the
// slicing of a wait are checked on a clock the test drives; on the steady clock every check uses
// deadlines that are either already past or many minutes away, so nothing here depends on how
// fast the machine is.
#include "replay/pacer.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <functional>
#include <thread>
#include <vector>

namespace gaitmon::replay {
namespace {

// Far enough ahead that no test run reaches it.
constexpr double kFarAheadS = 1000.0;

TEST(Pacer, MaxSpeedIsAlwaysDue) {
  std::atomic<bool> stop{false};
  Pacer pacer(kMaxSpeed, stop);
  EXPECT_TRUE(pacer.due(0.0));
  EXPECT_TRUE(pacer.due(kFarAheadS));
  EXPECT_TRUE(pacer.wait(2 * kFarAheadS));
}

TEST(Pacer, TheFirstFrameIsDueAtOnceWhateverItsTime) {
  std::atomic<bool> stop{false};
  Pacer pacer(1.0, stop);
  EXPECT_TRUE(pacer.due(5000.0));
  EXPECT_TRUE(pacer.due(5000.0));
  EXPECT_FALSE(pacer.due(5000.0 + kFarAheadS));
}

TEST(Pacer, TheFirstWaitAlsoSetsTheOrigin) {
  std::atomic<bool> stop{false};
  Pacer pacer(1.0, stop);
  EXPECT_TRUE(pacer.wait(300.0));
  EXPECT_TRUE(pacer.due(300.0));
  EXPECT_FALSE(pacer.due(300.0 + kFarAheadS));
}

// Division, not multiplication, by the speed. At x1e6 a tenth of a millisecond of session time
// is a tenth of a nanosecond, which the clock rounds to none (due at once; multiplied it would
// be 100 s); at x1e-6 it is 100 s (not due; multiplied it would be due at once).
TEST(Pacer, SpeedDividesTheSessionTime) {
  std::atomic<bool> stop{false};
  Pacer fast(1e6, stop);
  EXPECT_TRUE(fast.due(0.0));
  EXPECT_TRUE(fast.due(1e-4));
  EXPECT_TRUE(fast.wait(1e-4));

  Pacer slow(1e-6, stop);
  EXPECT_TRUE(slow.due(0.0));
  EXPECT_FALSE(slow.due(1e-4));
}

// Frames are never skipped: one behind the schedule, or before the first, is due at once.
TEST(Pacer, LateFramesAreDueAtOnce) {
  std::atomic<bool> stop{false};
  Pacer pacer(1.0, stop);
  EXPECT_TRUE(pacer.due(100.0));
  EXPECT_TRUE(pacer.due(50.0));
  EXPECT_TRUE(pacer.wait(-kFarAheadS));
}

TEST(Pacer, AStopSetBeforeWaitingEndsTheWait) {
  std::atomic<bool> stop{true};
  Pacer paced(1.0, stop);
  EXPECT_FALSE(paced.wait(0.0));
  Pacer unpaced(kMaxSpeed, stop);
  EXPECT_FALSE(unpaced.wait(0.0));
}

// A wait for a frame many minutes away returns false once another thread sets stop, whether it
// sees the flag before sleeping or between slices.
TEST(Pacer, AStopSetWhileWaitingEndsTheWait) {
  std::atomic<bool> stop{false};
  Pacer pacer(1.0, stop);
  ASSERT_TRUE(pacer.wait(0.0));
  std::thread stopper([&] { stop = true; });
  EXPECT_FALSE(pacer.wait(kFarAheadS));
  stopper.join();
}

// Time moves only when the pacer sleeps; each sleep is recorded, and a hook may act after one.
class ScriptedClock final : public PacerClock {
 public:
  time_point now() override { return now_; }
  void sleep_for(duration d) override {
    sleeps.push_back(d);
    now_ += d;
    if (after_sleep) after_sleep(sleeps.size());
  }
  void advance(duration d) { now_ += d; }
  std::chrono::nanoseconds since_start() const { return now_ - time_point{}; }

  std::vector<duration> sleeps;
  std::function<void(std::size_t)> after_sleep;

 private:
  time_point now_{};
};

using std::chrono::milliseconds;
using std::chrono::nanoseconds;

// At x2 a frame 0.5 s after the first is due 250 ms after it, exactly: not a nanosecond before.
TEST(Pacer, AFrameIsDueItsSessionTimeOverTheSpeedAfterTheFirst) {
  std::atomic<bool> stop{false};
  ScriptedClock clock;
  Pacer pacer(2.0, stop, clock);
  ASSERT_TRUE(pacer.due(10.0));
  clock.advance(milliseconds(250) - nanoseconds(1));
  EXPECT_FALSE(pacer.due(10.5));
  clock.advance(nanoseconds(1));
  EXPECT_TRUE(pacer.due(10.5));
  EXPECT_TRUE(clock.sleeps.empty());
}

// A wait sleeps exactly up to the deadline, in slices no longer than the stop poll interval:
// 250 ms is twelve slices of 20 ms and one of 10 ms.
TEST(Pacer, AWaitSleepsToTheDeadlineInSlicesOfThePollInterval) {
  std::atomic<bool> stop{false};
  ScriptedClock clock;
  Pacer pacer(2.0, stop, clock);
  ASSERT_TRUE(pacer.wait(10.0));
  EXPECT_TRUE(clock.sleeps.empty());
  ASSERT_TRUE(pacer.wait(10.5));
  EXPECT_EQ(clock.since_start(), milliseconds(250));
  ASSERT_EQ(clock.sleeps.size(), 13U);
  for (std::size_t i = 0; i < 12; ++i) EXPECT_EQ(clock.sleeps[i], Pacer::kStopPollInterval);
  EXPECT_EQ(clock.sleeps.back(), milliseconds(10));
  // The next frame's deadline runs from the first frame, not from the end of this wait.
  clock.advance(milliseconds(100));
  ASSERT_TRUE(pacer.wait(11.0));
  EXPECT_EQ(clock.since_start(), milliseconds(500));
}

// A wait that started late sleeps only for what is left, and one already behind not at all.
TEST(Pacer, ALateWaitSleepsOnlyForWhatIsLeft) {
  std::atomic<bool> stop{false};
  ScriptedClock clock;
  Pacer pacer(1.0, stop, clock);
  ASSERT_TRUE(pacer.wait(0.0));
  clock.advance(milliseconds(95));
  ASSERT_TRUE(pacer.wait(0.1));
  EXPECT_EQ(clock.sleeps, std::vector<PacerClock::duration>{milliseconds(5)});
  clock.advance(milliseconds(300));
  ASSERT_TRUE(pacer.wait(0.2));
  EXPECT_EQ(clock.sleeps.size(), 1U);
}

// A stop set during a long wait is seen at the end of the slice it came in: the wait returns
// false after three slices instead of sleeping the 10 s.
TEST(Pacer, AStopIsSeenWithinOnePollInterval) {
  std::atomic<bool> stop{false};
  ScriptedClock clock;
  clock.after_sleep = [&](std::size_t n) {
    if (n == 3) stop = true;
  };
  Pacer pacer(1.0, stop, clock);
  ASSERT_TRUE(pacer.wait(0.0));
  EXPECT_FALSE(pacer.wait(10.0));
  EXPECT_EQ(clock.sleeps.size(), 3U);
  EXPECT_EQ(clock.since_start(), 3 * Pacer::kStopPollInterval);
}

}  // namespace
}  // namespace gaitmon::replay
