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
  /// The same cov in the parameters' units, q x q by rows; NaN where se is.
  std::vector<double> cov;
  int moves = 0;  ///< how often the stencil's centre moved
};

/// Moves from `start` to the lowest point of the standard errors' stencil (steps of 3 % of each
/// value, at least 1e-4: the axis steps and, with two parameters, the four diagonal ones) until the
/// centre is the lowest, for at most 6 moves, and takes the standard errors there. Up to two
/// parameters.
SettledMinimum settle_on_stencil(SearchPoint start, const SearchBox& box,
                                 const SearchObjective& objective);

/// Standard errors that hold where the model's residuals are not independent, or the model not the
/// data's: the sandwich H^-1 B H^-1 with H^-1 = model_cov / 2 (model_cov = 2 H^-1, H the
/// deviance's Hessian) and B = G / (G - 1) sum over clusters of d_c d_c', d_c the sum of the
/// deviance's gradients of the cluster's units (`unit_gradients`, q each; `cluster_of` one per
/// unit). Units of one cluster may be correlated, clusters not. NaN for all where model_cov is, or
/// there are fewer than two clusters.
std::vector<double> clustered_sandwich_se(const std::vector<double>& model_cov,
                                          const std::vector<std::vector<double>>& unit_gradients,
                                          const std::vector<int>& cluster_of);

}  // namespace gaitmon::discrepancy_detail
