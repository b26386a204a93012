// The pacer's schedule: the first frame sets the origin, a frame is due (t - t_first) / speed
// after it, late frames are due at once, and stop ends a wait. Pacer has no clock seam, so
// every check uses deadlines that are either already past or many minutes away: nothing here
// depends on how fast the machine is.
#include "replay/pacer.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <thread>

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

}  // namespace
}  // namespace gaitmon::replay
