// The candidates' parameter search, kept apart from the workflow so that it can be tested on
// objectives with a known minimum and curvature. Internal: not part of the public API.
#pragma once

#include <functional>
#include <vector>

namespace gaitmon::discrepancy_detail {

/// The deviance to minimise at a parameter vector: -2 log-likelihood up to a constant, so that
/// cov = 2 H^-1 (with the force alone 2 s^2 H_SSE^-1, s^2 = SSE / N_eff, N_eff inflating for
/// autocorrelated residuals) and a rise of 1 is one standard error out. It may be called from
/// the thread that calls the search only.
using SearchObjective = std::function<double(const std::vector<double>&)>;

struct SearchPoint {
  std::vector<double> theta;
  double value = 0.0;
};

/// The parameters' ranges; the search never leaves them.
struct SearchBox {
  std::vector<double> lo, hi;
};

/// A pattern search from `start`: polls `step` along each parameter and, with two, along both
/// diagonals; moves to the first poll that improves, polling first the direction that last did,
/// and halves the steps where none does. Stops after 4 halvings or 40 moves.
SearchPoint pattern_search(SearchPoint start, std::vector<double> step, const SearchBox& box,
                           const SearchObjective& objective);

struct SettledMinimum {
  SearchPoint at;
  /// cov = 2 H^-1, H measured along the stencil Hessian's principal directions by secants over
  /// the step at which the deviance rises by 2 (at most 32 stencil steps, and not beyond the
  /// box). NaN where a secant's curvature is not positive. Not told apart for a parameter on a
  /// bound: the caller knows its ranges.
  std::vector<double> se;
  int moves = 0;  ///< how often the stencil's centre moved
};

/// Moves from `start` to the lowest point of the standard errors' stencil (steps of 3 % of each
/// value, at least 1e-4: the axis steps and, with two parameters, the four diagonal ones) until the
/// centre is the lowest, for at most 6 moves, and takes the standard errors there. Up to two
/// parameters.
SettledMinimum settle_on_stencil(SearchPoint start, const SearchBox& box,
                                 const SearchObjective& objective);

}  // namespace gaitmon::discrepancy_detail
