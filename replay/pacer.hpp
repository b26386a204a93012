// The replay clock: real time, scaled, or as fast as possible, interruptible by a stop flag.
#pragma once

#include <atomic>
#include <chrono>
#include <limits>

namespace gaitmon::replay {

/// speed = kMaxSpeed plays as fast as possible.
inline constexpr double kMaxSpeed = std::numeric_limits<double>::infinity();

/// Maps session time to wall time: the first frame waited for is due at once, a frame at
/// session time t is due (t - t_first) / speed later. Frames are never skipped: a late frame is
/// due at once.
class Pacer {
 public:
  /// speed > 0 (kMaxSpeed for no waiting). `stop` is polled at least every 20 ms while waiting.
  Pacer(double speed, const std::atomic<bool>& stop);

  /// Whether the frame at session time t_s is due now (always true at kMaxSpeed).
  bool due(double t_s);
  /// Waits until the frame at t_s is due. Returns false, early, once stop is set.
  bool wait(double t_s);

 private:
  std::chrono::steady_clock::time_point deadline(double t_s);

  double speed_;
  const std::atomic<bool>* stop_;
  bool started_ = false;
  double t_first_s_ = 0.0;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace gaitmon::replay
