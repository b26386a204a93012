// The replay clock: real time, scaled, or as fast as possible, interruptible by a stop flag.
#pragma once

#include <atomic>
#include <chrono>
#include <limits>

namespace gaitmon::replay {

/// speed = kMaxSpeed plays as fast as possible.
inline constexpr double kMaxSpeed = std::numeric_limits<double>::infinity();

/// The time a Pacer reads and sleeps on: the steady clock, or a test's own, so that a schedule
/// can be checked exactly without depending on how fast the machine is.
class PacerClock {
 public:
  using time_point = std::chrono::steady_clock::time_point;
  using duration = std::chrono::steady_clock::duration;
  virtual ~PacerClock() = default;
  virtual time_point now() = 0;
  virtual void sleep_for(duration d) = 0;
};

/// The steady clock and this_thread::sleep_for.
PacerClock& steady_pacer_clock();

/// Maps session time to wall time: the first frame waited for is due at once, a frame at
/// session time t is due (t - t_first) / speed later. Frames are never skipped: a late frame is
/// due at once.
class Pacer {
 public:
  /// Longest sleep between two looks at the stop flag.
  static constexpr std::chrono::milliseconds kStopPollInterval{20};

  /// speed > 0 (kMaxSpeed for no waiting). `stop` is polled at least every kStopPollInterval
  /// while waiting. `clock` must outlive the pacer.
  Pacer(double speed, const std::atomic<bool>& stop, PacerClock& clock = steady_pacer_clock());

  /// Whether the frame at session time t_s is due now (always true at kMaxSpeed).
  bool due(double t_s);
  /// Waits until the frame at t_s is due. Returns false, early, once stop is set.
  bool wait(double t_s);

 private:
  PacerClock::time_point deadline(double t_s);

  double speed_;
  const std::atomic<bool>* stop_;
  PacerClock* clock_;
  bool started_ = false;
  double t_first_s_ = 0.0;
  PacerClock::time_point start_;
};

}  // namespace gaitmon::replay
