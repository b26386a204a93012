// Replay pacing by sleeping in short slices, so a stop request is seen within 20 ms.
#include "replay/pacer.hpp"

#include <algorithm>
#include <cmath>
#include <thread>

namespace gaitmon::replay {

Pacer::Pacer(double speed, const std::atomic<bool>& stop) : speed_(speed), stop_(&stop) {}

std::chrono::steady_clock::time_point Pacer::deadline(double t_s) {
  if (!started_) {
    started_ = true;
    t_first_s_ = t_s;
    start_ = std::chrono::steady_clock::now();
  }
  const double wall_s = (t_s - t_first_s_) / speed_;
  return start_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                      std::chrono::duration<double>(std::max(0.0, wall_s)));
}

bool Pacer::due(double t_s) {
  if (std::isinf(speed_)) return true;
  return std::chrono::steady_clock::now() >= deadline(t_s);
}

bool Pacer::wait(double t_s) {
  if (stop_->load()) return false;
  if (std::isinf(speed_)) return true;
  const auto until = deadline(t_s);
  constexpr auto kSlice = std::chrono::milliseconds(20);
  for (auto now = std::chrono::steady_clock::now(); now < until;
       now = std::chrono::steady_clock::now()) {
    std::this_thread::sleep_for(std::min<std::chrono::steady_clock::duration>(until - now, kSlice));
    if (stop_->load()) return false;
  }
  return true;
}

}  // namespace gaitmon::replay
