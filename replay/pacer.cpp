// Replay pacing by sleeping in short slices, so a stop request is seen within 20 ms.
#include "replay/pacer.hpp"

#include <algorithm>
#include <cmath>
#include <thread>

namespace gaitmon::replay {

namespace {
class SteadyPacerClock final : public PacerClock {
 public:
  time_point now() override { return std::chrono::steady_clock::now(); }
  void sleep_for(duration d) override { std::this_thread::sleep_for(d); }
};
}  // namespace

PacerClock& steady_pacer_clock() {
  static SteadyPacerClock clock;
  return clock;
}

Pacer::Pacer(double speed, const std::atomic<bool>& stop, PacerClock& clock)
    : speed_(speed), stop_(&stop), clock_(&clock) {}

PacerClock::time_point Pacer::deadline(double t_s) {
  if (!started_) {
    started_ = true;
    t_first_s_ = t_s;
    start_ = clock_->now();
  }
  const double wall_s = (t_s - t_first_s_) / speed_;
  return start_ + std::chrono::duration_cast<PacerClock::duration>(
                      std::chrono::duration<double>(std::max(0.0, wall_s)));
}

bool Pacer::due(double t_s) {
  if (std::isinf(speed_)) return true;
  return clock_->now() >= deadline(t_s);
}

bool Pacer::wait(double t_s) {
  if (stop_->load()) return false;
  if (std::isinf(speed_)) return true;
  const auto until = deadline(t_s);
  for (auto now = clock_->now(); now < until; now = clock_->now()) {
    clock_->sleep_for(std::min<PacerClock::duration>(until - now, kStopPollInterval));
    if (stop_->load()) return false;
  }
  return true;
}

}  // namespace gaitmon::replay
