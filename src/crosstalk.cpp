// Undoing crosstalk between an insole's cells: one Cholesky factorisation per coupling.
#include "gaitmon/crosstalk.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace gaitmon {

CrosstalkCorrection::CrosstalkCorrection(const InsoleLayout& layout, double coupling)
    : coupling_(coupling) {
  if (!(coupling >= 0.0 && coupling <= kMaxCoupling)) {
    throw std::invalid_argument("crosstalk coupling " + std::to_string(coupling) +
                                " is outside [0, " + std::to_string(kMaxCoupling) + "]");
  }
  const auto n = static_cast<Eigen::Index>(layout.sensor_count());
  Eigen::MatrixXd mixing = Eigen::MatrixXd::Identity(n, n);
  for (std::size_t s = 0; s < layout.sensor_count(); ++s) {
    for (const Neighbour& nb : layout.neighbours(s)) {
      mixing(static_cast<Eigen::Index>(s), static_cast<Eigen::Index>(nb.sensor)) +=
          coupling * nb.shared_edge;
    }
  }
  mixing_.compute(mixing);
}

void CrosstalkCorrection::undo(std::span<double> readings) const {
  if (static_cast<Eigen::Index>(readings.size()) != mixing_.rows()) {
    throw std::invalid_argument("CrosstalkCorrection::undo: " + std::to_string(readings.size()) +
                                " readings for " + std::to_string(mixing_.rows()) + " sensors");
  }
  if (coupling_ == 0.0) return;
  Eigen::Map<Eigen::VectorXd> r(readings.data(), mixing_.rows());
  r = mixing_.solve(r);
}

}  // namespace gaitmon
