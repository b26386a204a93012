// Sensor creep undone in a recording's readings, so that each step's force and contact area are
// measured from what the cells would have read without it.
//
// Why: creep (a cell reading beta times its own load low-passed on top of it) changes the shape of
// the readings over a region, not only their sum. Each step's footprint then comes out narrower
// while the load rises (the loaded middle has crept more than the rim) and wider after the peak
// (cells the contact has left still read), on cells of either reading; and where a step's zeroing
// takes the creep's level off the swings, nothing on the force can give back the area. Measured on
// a 12-s session (size 41-42, seed 117, creep of gain 0.4 and tau 1 s): the held-out NRMSE of the
// baseline was 6.6 % on cells that average (1.6 % without creep) and 2.5 % on cells read at their
// centres (1.25 %); with the creep undone at its true parameters 1.7 and 1.3 % (README, "Sensor
// creep undone in the readings").
//
// Derivation: the creep of the simulator and of the discrepancy workflow's candidate reads
//     r_k = x_k + beta s_k,   s_k = s_{k-1} e + x_k (1 - e),   e = exp(-(t_k - t_{k-1}) / tau),
// with s starting at 0 on a cell's first frame. Given s_{k-1} and r_k that is linear in x_k:
//     x_k = (r_k - beta e s_{k-1}) / (1 + beta (1 - e)),
// exact, frame by frame, for any frame spacing. The readings carry the cell's dc bias, which the
// creep did not see; undoing it takes a constant bias c to c / (1 + beta) after a few tau, a
// constant that each step's zeroing takes off as it took c.
#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <span>
#include <vector>

#include "gaitmon/config.hpp"
#include "gaitmon/frame.hpp"
#include "gaitmon/segmentation.hpp"

namespace gaitmon {

/// Undoes creep of gain beta and time constant tau in a stream of frames, one lag per foot and
/// cell. Invariant: gain >= 0 and tau > 0, both finite. Frames of a foot must come in time order.
class CreepCorrection {
 public:
  /// Throws std::invalid_argument for a gain that is negative or a tau that is not positive
  /// (either not finite).
  CreepCorrection(double gain, double tau_s);
  double gain() const { return gain_; }
  double tau_s() const { return tau_s_; }

  /// What sensor `sensor` of `foot` would have read at `t_s` without creep, given that it read
  /// `reading` (bits). Throws std::invalid_argument if t_s is earlier than that cell's last frame
  /// or not finite.
  double undo(Foot foot, std::size_t sensor, double t_s, double reading);

  /// Replaces every cell's reading of the frame by undo's, rounded to whole bits within 0..255.
  void undo(Frame& frame);

 private:
  struct Lag {
    bool started = false;
    double t_s = 0.0;
    double value = 0.0;
  };
  double gain_;
  double tau_s_;
  std::array<std::vector<Lag>, 2> lags_;  ///< indexed by Foot, then sensor
};

/// One recording's fitted creep: gain and tau with their standard errors.
struct MeasuredCreep {
  double gain = 0.0;
  double gain_se = 0.0;
  double tau_s = 0.0;
  double tau_se_s = 0.0;
};

/// Whether several recordings of one pair of insoles show one creep. A creep of the insoles is the
/// same in every walk made on them; a creep that differs beyond the recordings' standard errors is
/// something else (a subject's loading, another pair).
struct CreepAgreement {
  std::size_t recordings = 0;
  /// Inverse-variance weighted means and their standard errors.
  MeasuredCreep mean;
  /// sum ((x_i - mean) / se_i)^2 over the recordings, for gain and tau, and the chance of one as
  /// large or larger from recordings of one creep: chi-square with recordings - 1 degrees of
  /// freedom.
  double gain_chi2 = 0.0;
  double tau_chi2 = 0.0;
  double gain_p = 1.0;
  double tau_p = 1.0;
  bool agree = false;  ///< both chances at least min_p
};

/// Throws std::invalid_argument for fewer than two creeps, a standard error that is not finite and
/// positive, or min_p outside (0, 1].
CreepAgreement creep_agreement(std::span<const MeasuredCreep> creeps, double min_p = 0.01);

/// The cells a walk's steps loaded that rest at 0 in the swing. A reading is clipped at 0, so a
/// cell whose zero is within the noise of 0 shows less of the creep it holds than it holds, and a
/// creep measured from the zeros comes out low (simulated walks of gain 0.2, noise 0.5 bits: 3 %
/// low where 9 % of the loaded cells rest at 0, 8.5 % where 25 % do, none where none do; README,
/// "Sensor creep of the insoles").
struct CellsAtZero {
  /// (step, cell) pairs where some stance frame read 2 bits or more over the step's zero.
  std::size_t loaded = 0;
  /// Of them, those whose zero (the mean of the step's swing windows) is under half a bit.
  std::size_t at_zero = 0;
  double pct() const {
    return loaded == 0 ? 0.0 : 100.0 * static_cast<double>(at_zero) / static_cast<double>(loaded);
  }
};

CellsAtZero loaded_cells_at_zero(std::span<const Step> steps);

/// The correction that undoes a config's [sensor_creep], or none when its gain is 0 (the readings
/// are then passed on untouched, not rounded again).
std::optional<CreepCorrection> creep_correction_of(const SensorCreepSettings& creep);

}  // namespace gaitmon
