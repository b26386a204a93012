// Undoes sensor creep in the readings (the inverse of the simulator's lag; see creep.hpp), and
// weighs whether several recordings show one creep.
#include "gaitmon/creep.hpp"

#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>
#include <stdexcept>
#include <string>
#include <tuple>

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

CellsAtZero loaded_cells_at_zero(std::span<const Step> steps) {
  constexpr double kLoadedBits = 2.0;
  constexpr double kAtZeroBits = 0.5;
  CellsAtZero out;
  for (const Step& step : steps) {
    const std::vector<double>& zero = step.sensor_zero_bits;
    std::vector<char> loaded(zero.size(), 0);
    for (const Frame& frame : step.stance) {
      for (std::size_t c = 0; c < frame.bits.size() && c < zero.size(); ++c) {
        if (frame.bits[c] - zero[c] >= kLoadedBits) loaded[c] = 1;
      }
    }
    for (std::size_t c = 0; c < zero.size(); ++c) {
      if (!loaded[c]) continue;
      ++out.loaded;
      if (zero[c] < kAtZeroBits) ++out.at_zero;
    }
  }
  return out;
}

std::optional<CreepCorrection> creep_correction_of(const SensorCreepSettings& creep) {
  if (creep.gain == 0.0) return std::nullopt;
  return CreepCorrection(creep.gain, creep.tau_s);
}

CreepAgreement creep_agreement(std::span<const MeasuredCreep> creeps, double min_p) {
  if (creeps.size() < 2) {
    throw std::invalid_argument("creep agreement: needs two recordings or more, got " +
                                std::to_string(creeps.size()));
  }
  if (!(min_p > 0.0 && min_p <= 1.0)) {
    throw std::invalid_argument("creep agreement: min_p must be in (0, 1], not " +
                                std::to_string(min_p));
  }
  const auto good_se = [](double se) { return std::isfinite(se) && se > 0.0; };
  for (const MeasuredCreep& c : creeps) {
    if (!good_se(c.gain_se) || !good_se(c.tau_se_s)) {
      throw std::invalid_argument("creep agreement: a recording's creep has no standard error");
    }
  }
  // The weighted mean of one parameter, its standard error, and the chi-square about it.
  const auto pool = [&](double MeasuredCreep::*value, double MeasuredCreep::*se) {
    double weights = 0.0;
    double sum = 0.0;
    for (const MeasuredCreep& c : creeps) {
      const double w = 1.0 / (c.*se * c.*se);
      weights += w;
      sum += w * c.*value;
    }
    const double mean = sum / weights;
    double chi2 = 0.0;
    for (const MeasuredCreep& c : creeps) chi2 += std::pow((c.*value - mean) / c.*se, 2);
    return std::tuple{mean, 1.0 / std::sqrt(weights), chi2};
  };
  CreepAgreement out;
  out.recordings = creeps.size();
  std::tie(out.mean.gain, out.mean.gain_se, out.gain_chi2) =
      pool(&MeasuredCreep::gain, &MeasuredCreep::gain_se);
  std::tie(out.mean.tau_s, out.mean.tau_se_s, out.tau_chi2) =
      pool(&MeasuredCreep::tau_s, &MeasuredCreep::tau_se_s);
  const boost::math::chi_squared chi2(static_cast<double>(creeps.size() - 1));
  out.gain_p = boost::math::cdf(boost::math::complement(chi2, out.gain_chi2));
  out.tau_p = boost::math::cdf(boost::math::complement(chi2, out.tau_chi2));
  out.agree = out.gain_p >= min_p && out.tau_p >= min_p;
  return out;
}

}  // namespace gaitmon
