// The candidates' parameter search: a pattern search, then a settling on the standard errors'
// stencil so that its curvature is taken where the deviance is lowest at the stencil's scale.
#include "discrepancy_search.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <map>
#include <stdexcept>
#include <utility>

namespace gaitmon::discrepancy_detail {
namespace {

// A bound on the work; a search that starts on the grid's best point settles in far fewer.
constexpr int kPatternHalvings = 4;
constexpr int kPatternMoves = 40;
constexpr int kSettleMoves = 6;

// The pattern search's polls and the stencil's points, in units of their steps: each axis
// both ways, then (two parameters) the diagonals, since relaxation's strength and tau trade off
// along one, which axis polls alone leave early. The stencil's Hessian reads them in this order.
std::vector<std::vector<double>> poll_offsets(std::size_t q) {
  std::vector<std::vector<double>> out;
  for (std::size_t p = 0; p < q; ++p) {
    for (double sign : {-1.0, 1.0}) {
      out.emplace_back(q, 0.0);
      out.back()[p] = sign;
    }
  }
  if (q == 2) {
    for (double a : {-1.0, 1.0}) {
      for (double b : {-1.0, 1.0}) out.push_back({a, b});
    }
  }
  return out;
}

std::vector<double> offset_point(const std::vector<double>& theta, const std::vector<double>& by,
                                 const std::vector<double>& step) {
  auto out = theta;
  for (std::size_t p = 0; p < out.size(); ++p) out[p] += by[p] * step[p];
  return out;
}

bool inside(const std::vector<double>& theta, const SearchBox& box) {
  for (std::size_t p = 0; p < theta.size(); ++p) {
    if (theta[p] < box.lo[p] || theta[p] > box.hi[p]) return false;
  }
  return true;
}

// The stencil's Hessian in units of its steps, from its values around `centre` (in
// poll_offsets' order).
std::vector<double> stencil_hessian(double centre, const std::vector<double>& values,
                                    std::size_t q) {
  std::vector<double> H(q * q, 0.0);
  for (std::size_t i = 0; i < q; ++i) H[i * q + i] = values[2 * i] - 2 * centre + values[2 * i + 1];
  // (-,-), (-,+), (+,-), (+,+)
  if (q == 2) H[1] = H[2] = (values[4] - values[5] - values[6] + values[7]) / 4;
  return H;
}

// Unit eigenvectors of a symmetric matrix of order 1 or 2.
std::vector<std::vector<double>> principal_directions(const std::vector<double>& H, std::size_t q) {
  if (q == 1) return {{1.0}};
  const double angle = 0.5 * std::atan2(2 * H[1], H[0] - H[3]);
  return {{std::cos(angle), std::sin(angle)}, {-std::sin(angle), std::cos(angle)}};
}

// Along a direction where the deviance is nearly flat, as along the valley where relaxation's
// strength and tau trade off, the kinks of the profile (a unit's n moving to the next of its
// grid values; some tenths of a deviance unit) are as large as the rise over one stencil step,
// and a curvature taken there can have either sign: the session of relaxation 0.5 and 0.2 s
// (size 41-42, seed 301) came out without a standard error so. Along each principal direction
// of the stencil's Hessian the step therefore doubles until the deviance rises by 2 (a profile
// interval of about 1.4 SE, where the kinks are a small part of the rise) or the next step
// would leave the box, and the secant's curvature is taken over that step. On a quadratic
// every step gives the same curvature.
constexpr double kRise = 2.0;
constexpr int kMaxDoublings = 5;

// cov = 2 H^-1 in the parameters' units, q x q by rows; all NaN where a curvature is not positive.
std::vector<double> secant_covariance(const SearchPoint& at, const std::vector<double>& h,
                                      const std::vector<double>& stencil_H, const SearchBox& box,
                                      const SearchObjective& objective) {
  const std::size_t q = h.size();
  const auto directions = principal_directions(stencil_H, q);
  const auto along = [&](const std::vector<double>& v, double s) {
    auto th = at.theta;
    for (std::size_t p = 0; p < q; ++p) th[p] += s * v[p] * h[p];
    return th;
  };
  // cov = 2 H^-1 = V diag(2 / c) V' in the steps' units, scaled to the parameters'.
  std::vector<double> cov(q * q, 0.0);
  for (const auto& v : directions) {
    double s = 1.0;
    double rise = 0.0;
    for (int k = 0; k <= kMaxDoublings; ++k) {
      rise = 0.5 * (objective(along(v, s)) + objective(along(v, -s))) - at.value;
      if (rise >= kRise || k == kMaxDoublings || !inside(along(v, 2 * s), box) ||
          !inside(along(v, -2 * s), box)) {
        break;
      }
      s *= 2;
    }
    const double c = 2 * rise / (s * s);
    if (!(c > 0)) return std::vector<double>(q * q, std::numeric_limits<double>::quiet_NaN());
    for (std::size_t i = 0; i < q; ++i) {
      for (std::size_t j = 0; j < q; ++j) cov[i * q + j] += 2.0 / c * v[i] * v[j] * h[i] * h[j];
    }
  }
  return cov;
}

// The step of the standard errors' difference stencil.
std::vector<double> stencil_steps(const std::vector<double>& theta) {
  // The profile has kinks where a unit's n moves to the next of its grid values; a step of 1 %
  // could straddle one and give a curvature of either sign (stress relaxation's strength 0.56
  // and tau 0.83 s, both well inside their ranges, came out without an SE), so the step spans
  // 3 % and averages over them.
  std::vector<double> h(theta.size());
  for (std::size_t i = 0; i < h.size(); ++i) h[i] = std::max(1e-4, 3e-2 * std::abs(theta[i]));
  return h;
}

}  // namespace

SearchPoint pattern_search(SearchPoint start, std::vector<double> step, const SearchBox& box,
                           const SearchObjective& objective) {
  SearchPoint at = std::move(start);
  const std::size_t q = at.theta.size();
  const auto directions = poll_offsets(q);
  // Polls start with the direction that last improved, so a walk along a valley costs one
  // evaluation a move.
  std::size_t first = 0;
  for (int halvings = 0, moves = 0; halvings < kPatternHalvings && moves < kPatternMoves;) {
    bool moved = false;
    for (std::size_t k = 0; k < directions.size() && !moved; ++k) {
      const std::size_t d = (first + k) % directions.size();
      auto trial = offset_point(at.theta, directions[d], step);
      for (std::size_t p = 0; p < q; ++p) trial[p] = std::clamp(trial[p], box.lo[p], box.hi[p]);
      if (trial == at.theta) continue;
      const double v = objective(trial);
      if (v < at.value) {
        at = {std::move(trial), v};
        first = d;
        moved = true;
      }
    }
    if (moved) {
      ++moves;
    } else {
      for (double& s : step) s *= 0.5;
      ++halvings;
    }
  }
  return at;
}

// The pattern search stops where its own polls, finer than the stencil by the end, find nothing
// lower; over the kinks a point of the stencil can still be lower than its centre. A curvature
// taken there is that of a slope, not of a minimum, and can come out indefinite: a change of
// 1e-4 of the peak force in the data was enough to lose relaxation's standard errors so.
SettledMinimum settle_on_stencil(SearchPoint start, const SearchBox& box,
                                 const SearchObjective& objective) {
  const std::size_t q = start.theta.size();
  if (q == 0 || q > 2) throw std::invalid_argument("settle_on_stencil: one or two parameters");
  SettledMinimum out{std::move(start), {}, {}, 0};
  const auto offsets = poll_offsets(q);
  std::vector<double> values(offsets.size());
  for (;;) {
    const auto h = stencil_steps(out.at.theta);
    std::size_t lowest = offsets.size();
    for (std::size_t k = 0; k < offsets.size(); ++k) {
      const auto point = offset_point(out.at.theta, offsets[k], h);
      values[k] = objective(point);
      const double best = lowest < offsets.size() ? values[lowest] : out.at.value;
      if (inside(point, box) && values[k] < best) lowest = k;
    }
    if (lowest == offsets.size() || out.moves == kSettleMoves) {
      out.cov =
          secant_covariance(out.at, h, stencil_hessian(out.at.value, values, q), box, objective);
      out.se.resize(q);
      for (std::size_t i = 0; i < q; ++i) out.se[i] = std::sqrt(out.cov[i * q + i]);
      return out;
    }
    out.at = {offset_point(out.at.theta, offsets[lowest], h), values[lowest]};
    ++out.moves;
  }
}

std::vector<double> clustered_sandwich_se(const std::vector<double>& model_cov,
                                          const std::vector<std::vector<double>>& unit_gradients,
                                          const std::vector<int>& cluster_of) {
  const std::size_t q2 = model_cov.size();
  const auto q = static_cast<std::size_t>(std::lround(std::sqrt(static_cast<double>(q2))));
  if (q == 0 || q * q != q2 || unit_gradients.size() != cluster_of.size()) {
    throw std::invalid_argument("clustered_sandwich_se: a q x q covariance and one cluster a unit");
  }
  const std::vector<double> none(q, std::numeric_limits<double>::quiet_NaN());
  if (!std::all_of(model_cov.begin(), model_cov.end(), [](double v) { return std::isfinite(v); })) {
    return none;
  }
  std::map<int, std::vector<double>> sums;
  for (std::size_t u = 0; u < unit_gradients.size(); ++u) {
    if (unit_gradients[u].size() != q) {
      throw std::invalid_argument("clustered_sandwich_se: q gradients a unit");
    }
    std::vector<double>& d = sums.try_emplace(cluster_of[u], q, 0.0).first->second;
    for (std::size_t p = 0; p < q; ++p) d[p] += unit_gradients[u][p];
  }
  if (sums.size() < 2) return none;
  const auto g = static_cast<double>(sums.size());
  std::vector<double> B(q * q, 0.0);
  for (const auto& [cluster, d] : sums) {
    for (std::size_t i = 0; i < q; ++i) {
      for (std::size_t j = 0; j < q; ++j) B[i * q + j] += g / (g - 1) * d[i] * d[j];
    }
  }
  std::vector<double> se(q);
  for (std::size_t p = 0; p < q; ++p) {
    double v = 0.0;
    for (std::size_t i = 0; i < q; ++i) {
      for (std::size_t j = 0; j < q; ++j) {
        v += 0.5 * model_cov[p * q + i] * B[i * q + j] * 0.5 * model_cov[j * q + p];
      }
    }
    se[p] = std::sqrt(v);
  }
  return se;
}

}  // namespace gaitmon::discrepancy_detail
