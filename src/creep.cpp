// Undoes sensor creep in the readings (the inverse of the simulator's lag; see creep.hpp).
#include "gaitmon/creep.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace gaitmon {

CreepCorrection::CreepCorrection(double gain, double tau_s) : gain_(gain), tau_s_(tau_s) {
  if (!(gain >= 0.0) || !std::isfinite(gain)) {
    throw std::invalid_argument("creep correction: the gain must be finite and at least 0, not " +
                                std::to_string(gain));
  }
  if (!(tau_s > 0.0) || !std::isfinite(tau_s)) {
    throw std::invalid_argument("creep correction: tau must be finite and positive, not " +
                                std::to_string(tau_s) + " s");
  }
}

double CreepCorrection::undo(Foot foot, std::size_t sensor, double t_s, double reading) {
  std::vector<Lag>& lags = lags_[static_cast<std::size_t>(foot)];
  if (sensor >= lags.size()) lags.resize(sensor + 1);
  Lag& lag = lags[sensor];
  if (!std::isfinite(t_s) || (lag.started && t_s < lag.t_s)) {
    throw std::invalid_argument("creep correction: frame at " + std::to_string(t_s) +
                                " s is not after the cell's last one at " +
                                std::to_string(lag.t_s) + " s");
  }
  if (!lag.started) lag = {true, t_s, 0.0};
  const double keep = std::exp(-(t_s - lag.t_s) / tau_s_);
  const double own = (reading - gain_ * keep * lag.value) / (1.0 + gain_ * (1.0 - keep));
  lag.value = lag.value * keep + own * (1.0 - keep);
  lag.t_s = t_s;
  return own;
}

void CreepCorrection::undo(Frame& frame) {
  for (std::size_t i = 0; i < frame.bits.size(); ++i) {
    const double own = undo(frame.foot, i, frame.t_s, frame.bits[i]);
    frame.bits[i] = static_cast<std::uint8_t>(std::clamp(std::round(own), 0.0, 255.0));
  }
}

std::optional<CreepCorrection> creep_correction_of(const SensorCreepSettings& creep) {
  if (creep.gain == 0.0) return std::nullopt;
  return CreepCorrection(creep.gain, creep.tau_s);
}

}  // namespace gaitmon
