// Crosstalk between an insole's cells: each cell also reads a share of what the cells it shares
// an edge with read. Undone here, so that a footprint can be measured from what the cells would
// have read on their own.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <span>

#include "gaitmon/insole.hpp"

namespace gaitmon {

/// Readings r = (I + k W) b, with W_ij the share of the edge cells i and j have in common
/// (InsoleLayout::neighbours) and k the coupling per whole edge, give back b. Invariant: the
/// coupling is in [0, kMaxCoupling], where I + k W stays positive definite (W's
/// eigenvalues lie within [-4, 4]: a cell's shares add up to at most two side edges and a
/// cell's width in each row next to its own).
class CrosstalkCorrection {
 public:
  static constexpr double kMaxCoupling = 0.24;
  /// Throws std::invalid_argument for a coupling outside [0, kMaxCoupling].
  CrosstalkCorrection(const InsoleLayout& layout, double coupling);
  double coupling() const { return coupling_; }
  /// Replaces each cell's reading (zeroed, in bits, one per sensor in sensor order) by what it
  /// would have read without its neighbours. Throws std::invalid_argument for a wrong count.
  void undo(std::span<double> readings) const;

 private:
  double coupling_;
  Eigen::LLT<Eigen::MatrixXd> mixing_;
};

}  // namespace gaitmon
