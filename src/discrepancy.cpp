// The discrepancy workflow: baseline as nested linear amplitudes, candidate effects on a shared
// parameter grid with k-fold held-out error and BIC, residual maps and diagnostics.
#include "gaitmon/discrepancy.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <stop_token>
#include <tuple>
#include <utility>

#include "discrepancy_diagnostics.hpp"
#include "discrepancy_effects.hpp"
#include "discrepancy_search.hpp"
#include "gaitmon/crosstalk.hpp"
#include "gaitmon/stance.hpp"
#include "parallel_for.hpp"

namespace gaitmon {
namespace {

constexpr double kMaxAreaFraction = 0.999;  // as tissue_fit: g stays finite at the equator
constexpr int kMinContactFrames = 5;
constexpr std::array<double, 9> kExponentGrid{0.01, 0.12, 0.25, 0.38, 0.5, 0.62, 0.75, 0.88, 0.98};

using detail::parallel_for;
using discrepancy_detail::Applied;
using discrepancy_detail::candidate_specs;
using discrepancy_detail::CandidateSpec;
using discrepancy_detail::clustered_sandwich_se;
using discrepancy_detail::diagnose;
using discrepancy_detail::kCrosstalk;
using discrepancy_detail::ParamSpec;
using discrepancy_detail::pattern_search;
using discrepancy_detail::residual_map;
using discrepancy_detail::savgol_noise_sd;
using discrepancy_detail::SearchBox;
using discrepancy_detail::SearchObjective;
using discrepancy_detail::SearchPoint;
using discrepancy_detail::settle_on_stencil;
using discrepancy_detail::SettledMinimum;
using discrepancy_detail::Unit;

double g_of(double area, double P) {
  const double a = std::min(area / P, kMaxAreaFraction);
  return 1.0 - std::sqrt(1.0 - a);
}

}  // namespace

// The elastic and damping shapes of one series (tissue_fit's raw-series model).
discrepancy_detail::Shapes discrepancy_detail::shapes_of(std::span<const double> t_s,
                                                         std::span<const double> area_mm2,
                                                         const ShapeModel& m) {
  const std::size_t n = t_s.size();
  const IdentifiableParams& id = m.id;
  Shapes out;
  out.En.assign(1 + kExponentGrid.size(), std::vector<double>(n, 0.0));
  out.V.assign(n, 0.0);
  out.d_mm.assign(n, 0.0);
  out.ddot_mm_per_s.assign(n, 0.0);
  for (const auto [begin, end] : contact_runs(area_mm2)) {
    for (std::size_t i = begin; i < end; ++i) {
      const std::size_t lo = i > begin ? i - 1 : i;
      const std::size_t hi = i + 1 < end ? i + 1 : i;
      const double g = g_of(area_mm2[i], id.P_mm2);
      const double dt = t_s[hi] - t_s[lo];
      const double gdot =
          hi > lo ? (g_of(area_mm2[hi], id.P_mm2) - g_of(area_mm2[lo], id.P_mm2)) / dt : 0.0;
      out.En[0][i] = id.P_mm2 * std::pow(g, 2.0 + id.n) * (1.0 - g / 3.0);
      for (std::size_t k = 0; k < kExponentGrid.size(); ++k) {
        out.En[k + 1][i] = id.P_mm2 * std::pow(g, 2.0 + kExponentGrid[k]) * (1.0 - g / 3.0);
      }
      out.V[i] = damping_sign(m.model) * id.P_mm2 * std::pow(g, 1.0 + id.m) * gdot *
                 damping_shape(g, m.model);
      out.d_mm[i] = g * m.C_mm;
      out.ddot_mm_per_s[i] = gdot * m.C_mm;
    }
  }
  return out;
}

namespace {

// The two columns' products, for solving against many y.
struct Gram2 {
  double xx = 0, xz = 0, zz = 0;
};

Gram2 gram2(std::span<const double> x, std::span<const double> z) {
  Gram2 g;
  for (std::size_t i = 0; i < x.size(); ++i) {
    g.xx += x[i] * x[i];
    g.xz += x[i] * z[i];
    g.zz += z[i] * z[i];
  }
  return g;
}

// Non-negative least squares of y on two columns (a x + b z).
std::pair<double, double> nnls2(std::span<const double> y, std::span<const double> x,
                                std::span<const double> z, const Gram2& g) {
  const auto [xx, xz, zz] = g;
  double xy = 0, zy = 0;
  for (std::size_t i = 0; i < y.size(); ++i) {
    xy += x[i] * y[i];
    zy += z[i] * y[i];
  }
  const double det = xx * zz - xz * xz;
  if (det > 1e-12 * xx * zz && xx > 0 && zz > 0) {
    const double a = (xy * zz - zy * xz) / det;
    const double b = (zy * xx - xy * xz) / det;
    if (a >= 0 && b >= 0) return {a, b};
  }
  const double a_only = xx > 0 ? std::max(0.0, xy / xx) : 0.0;
  const double b_only = zz > 0 ? std::max(0.0, zy / zz) : 0.0;
  const auto sse = [&](double a, double b) {
    double s = 0;
    for (std::size_t i = 0; i < y.size(); ++i) {
      const double r = y[i] - a * x[i] - b * z[i];
      s += r * r;
    }
    return s;
  };
  return sse(a_only, 0.0) <= sse(0.0, b_only) ? std::pair{a_only, 0.0} : std::pair{0.0, b_only};
}

std::pair<double, double> nnls2(std::span<const double> y, std::span<const double> x,
                                std::span<const double> z) {
  return nnls2(y, x, z, gram2(x, z));
}

// ---- fitting ----------------------------------------------------------------------------------

// A chain of applied effects in physical order (tissue, then sensor).
using Chain = std::vector<const Applied*>;

struct Workspace {
  std::vector<double> F, a, f, f0, fk, fd, lin, slope, zeros, off, at_zero, target, tv;
  std::vector<std::vector<double>> te;
  std::vector<Gram2> gram;
};

// `seen` is the unit as the whole chain sees it (seen_under), which `chain`, a part of it, need
// not show. `skip_additive` leaves out the effects that only add to F.
void run_chain(const Chain& chain, std::size_t ui, const Unit& u, const Unit& seen,
               std::span<const double> F, std::span<double> out, Workspace& w, std::size_t choice,
               bool skip_additive = false) {
  std::copy(F.begin(), F.end(), out.begin());
  for (const Applied* e : chain) {
    if (!e->affects(u) || (skip_additive && e->additive())) continue;
    w.a.assign(out.begin(), out.end());
    e->apply(ui, seen, w.a, out, std::min(choice, e->choices(u) - 1));
  }
}

// The unit as the chain sees it: as an effect on the measurement the model is driven by
// corrects it (crosstalk's corrected area, and the shapes and deformation from it), or as
// measured.
const Unit& seen_under(const Chain& chain, std::size_t ui, const Unit& u) {
  for (const Applied* e : chain) {
    if (!e->affects(u)) continue;
    if (const Unit* v = e->seen(ui)) return *v;
  }
  return u;
}

double sse_of(std::span<const double> y, std::span<const double> f) {
  double s = 0;
  for (std::size_t i = 0; i < y.size(); ++i) s += (y[i] - f[i]) * (y[i] - f[i]);
  return s;
}

// The best of one unit's re-solutions so far: the sum of squared residuals, n's grid index, the
// effects' per-step choice, K and D.
struct UnitSolution {
  double sse = std::numeric_limits<double>::infinity();
  std::size_t k = 0, choice = 0;
  double K = 0.0, D = 0.0;
  void offer(double s, std::size_t k_, std::size_t c, double K_, double D_) {
    if (s < sse) *this = {s, k_, c, K_, D_};
  }
};

// Gauss-Newton on K, D >= 0 for the model force off + K te + D tv (w's) through `rest`, from
// (K, D); returns the sum of squared residuals there. Where `rest` affects the unit with one
// effect (`sole`) that gives its slope, the derivatives are exact and each step runs it once;
// otherwise forward differences.
double refine(const Chain& rest, const Applied* sole, std::size_t ui, const Unit& u,
              const Unit& seen, std::size_t c, const std::vector<double>& te, Workspace& w,
              double& K, double& D) {
  const std::size_t n = u.y.size();
  w.slope.resize(n);
  w.fk.resize(n);
  w.fd.resize(n);
  // Returns whether w.slope holds the slope at the point.
  const auto model = [&](double K_, double D_) {
    for (std::size_t i = 0; i < n; ++i) w.F[i] = w.off[i] + K_ * te[i] + D_ * w.tv[i];
    if (sole != nullptr && sole->apply_with_slope(ui, seen, w.F, w.f, w.slope)) return true;
    run_chain(rest, ui, u, seen, w.F, w.f, w, c);
    return false;
  };
  bool exact = model(K, D);
  double value = sse_of(u.y, w.f);
  // w.f (and w.slope) hold the model at (K, D) at the top of every iteration: the line search
  // ends on the point it accepts.
  for (int it = 0; it < 6; ++it) {
    w.f0 = w.f;
    if (exact) {
      for (std::size_t i = 0; i < n; ++i) {
        w.fk[i] = w.slope[i] * te[i];
        w.fd[i] = w.slope[i] * w.tv[i];
      }
    } else {
      const double hK = std::max(1e-9, 1e-4 * std::abs(K));
      const double hD = std::max(1e-9, 1e-4 * std::abs(D));
      model(K + hK, D);
      w.fk = w.f;
      model(K, D + hD);
      w.fd = w.f;
      for (std::size_t i = 0; i < n; ++i) {
        w.fk[i] = (w.fk[i] - w.f0[i]) / hK;
        w.fd[i] = (w.fd[i] - w.f0[i]) / hD;
      }
    }
    for (std::size_t i = 0; i < n; ++i)
      w.lin[i] = u.y[i] - w.f0[i] + K * w.fk[i] + D * w.fd[i];  // the linearised target
    const auto [K1, D1] = nnls2(w.lin, w.fk, w.fd);
    double step = 1.0;
    double after = value;
    for (int halving = 0; halving < 6; ++halving, step *= 0.5) {
      exact = model(K + step * (K1 - K), D + step * (D1 - D));
      after = sse_of(u.y, w.f);
      if (after <= value) break;
    }
    if (after > value) break;
    K += step * (K1 - K);
    D += step * (D1 - D);
    const bool done = value - after <= 1e-9 * value;
    value = after;
    if (done) break;
  }
  return value;
}

// The chain up to its first effect that is not affine in F (saturation) is affine: there the
// force is T(0) + K L(E) + D L(V), with L(x) = T(x) - T(0) the prefix's linear part. So L(E) per
// exponent and L(V) are computed once per choice, and K, D >= 0 solve exactly when nothing
// follows; what does follow is refined by Gauss-Newton from that solution, which then only runs
// the rest of the chain. An effect that only adds to F is all in T(0), so L is computed without
// it; where such effects alone vary with the step's choice (impact's onset), L is the same for
// every choice and is computed once: it took 12 runs of the chain per choice, and impact has 21.
void solve_chain(const Chain& chain, std::size_t ui, const Unit& u, std::size_t choices,
                 Workspace& w, UnitSolution& best) {
  const std::size_t n = u.y.size();
  const Unit& sh = seen_under(chain, ui, u);
  const auto first_nonlinear = std::find_if(
      chain.begin(), chain.end(), [&](const Applied* e) { return e->affects(u) && !e->affine(); });
  const Chain prefix(chain.begin(), first_nonlinear);
  const Chain rest(first_nonlinear, chain.end());
  const auto rest_active =
      std::count_if(rest.begin(), rest.end(), [&](const Applied* e) { return e->affects(u); });
  const Applied* sole = rest_active == 1 ? *first_nonlinear : nullptr;
  bool adds = false;
  bool linear_varies = false;
  for (const Applied* e : prefix) {
    if (!e->affects(u)) continue;
    adds = adds || e->additive();
    linear_varies = linear_varies || (!e->additive() && e->choices(u) > 1);
  }
  w.zeros.assign(n, 0.0);
  w.off.resize(n);
  w.at_zero.resize(n);
  w.target.resize(n);
  w.lin.resize(n);
  w.tv.resize(n);
  w.te.resize(sh.En.size());
  w.gram.resize(sh.En.size());
  const auto linear = [&](std::span<const double> x, std::vector<double>& out, std::size_t c) {
    out.resize(n);
    run_chain(prefix, ui, u, sh, x, out, w, c, true);
    for (std::size_t i = 0; i < n; ++i) out[i] -= w.at_zero[i];
  };
  for (std::size_t c = 0; c < choices; ++c) {
    run_chain(prefix, ui, u, sh, w.zeros, w.off, w, c);
    if (c == 0 || linear_varies) {
      if (adds) {
        run_chain(prefix, ui, u, sh, w.zeros, w.at_zero, w, c, true);
      } else {
        w.at_zero = w.off;
      }
      linear(sh.V, w.tv, c);
      for (std::size_t k = 0; k < sh.En.size(); ++k) {
        linear(sh.En[k], w.te[k], c);
        w.gram[k] = gram2(w.te[k], w.tv);
      }
    }
    for (std::size_t i = 0; i < n; ++i) w.target[i] = u.y[i] - w.off[i];
    for (std::size_t k = 0; k < sh.En.size(); ++k) {
      const std::vector<double>& te = w.te[k];
      auto [K, D] = nnls2(w.target, te, w.tv, w.gram[k]);
      if (rest.empty()) {
        double s = 0;
        for (std::size_t i = 0; i < n; ++i) {
          const double r = w.target[i] - K * te[i] - D * w.tv[i];
          s += r * r;
        }
        best.offer(s, k, c, K, D);
        continue;
      }
      const double value = refine(rest, sole, ui, u, sh, c, te, w, K, D);
      best.offer(value, k, c, K, D);
    }
  }
}

// Re-solves one unit under the chain: the exponent n from the unit's grid, the effects' per-step
// choice, and K, D >= 0 by least squares. Returns the sum of squared residuals; fills `pred` if
// given. A unit no effect touches keeps its baseline.
double solve_unit(const Chain& chain, std::size_t ui, const Unit& u, Workspace& w,
                  std::vector<double>* pred = nullptr, bool baseline = false) {
  bool active = false;
  std::size_t choices = 1;
  for (const Applied* e : chain) {
    if (e->affects(u)) {
      active = true;
      choices = std::max(choices, e->choices(u));
    }
  }
  if (!active && !baseline) {
    if (pred != nullptr) *pred = u.base_pred;
    return u.base_sse;
  }
  w.F.resize(u.y.size());
  w.f.resize(u.y.size());
  UnitSolution best;
  solve_chain(chain, ui, u, choices, w, best);
  if (pred != nullptr) {
    const Unit& sh = seen_under(chain, ui, u);
    for (std::size_t i = 0; i < u.y.size(); ++i) {
      w.F[i] = best.K * sh.En[best.k][i] + best.D * sh.V[i];
    }
    run_chain(chain, ui, u, sh, w.F, w.f, w, best.choice);
    *pred = w.f;
  }
  return best.sse;
}

// A model's effects in the order given; the chain runs them in physical order, by stage and in
// the order given within one.
struct Model {
  std::vector<std::shared_ptr<const Applied>> owned;
  std::vector<int> stages;

  Chain chain() const {
    std::vector<std::size_t> order(owned.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return stages[a] < stages[b]; });
    Chain c;
    for (std::size_t i : order) c.push_back(owned[i].get());
    return c;
  }
};

// An effect at fixed parameters, made ready for the units once where it is evaluated under
// many others (the first effect under each second candidate): crosstalk's corrected units take
// longer to make than the chain takes to run.
struct FixedEffect {
  const CandidateSpec* spec;
  std::vector<double> theta;
  std::shared_ptr<const Applied> made = nullptr;
};

Model build(const std::vector<Unit>& units, std::span<const FixedEffect> effects) {
  Model m;
  for (const FixedEffect& e : effects) {
    m.owned.push_back(e.made != nullptr ? e.made : e.spec->make(units, e.theta));
    m.stages.push_back(e.spec->stage);
  }
  return m;
}

double sum(std::span<const double> v) {
  double s = 0;
  for (double x : v) s += x;
  return s;
}

// Squared residuals per unit of the two channels: the stance force, and the change of the
// unit's zero from the foot's step before (0 where it is not observed).
struct Costs {
  std::vector<double> force, zero;
  double force_sse() const { return sum(force); }
  double zero_sse() const { return sum(zero); }
};

Costs unit_costs(const std::vector<Unit>& units, std::span<const FixedEffect> fx,
                 std::vector<std::vector<double>>* preds = nullptr) {
  const Model m = build(units, fx);
  const Chain chain = m.chain();
  Costs cost{std::vector<double>(units.size(), 0.0), std::vector<double>(units.size(), 0.0)};
  Workspace w;
  if (preds != nullptr) preds->resize(units.size());
  // Per unit with an observed change: the change less the chain's prediction without an
  // unknown start (rest), and the prediction per unit of start lag (slope).
  std::vector<double> rest(units.size(), 0.0), slope(units.size(), 0.0);
  const auto reading = [&](std::size_t ui) {
    double level = 0.0, per_start = 0.0;
    for (const Applied* e : chain) {
      level += e->swing_reading(ui);
      per_start += e->swing_reading_per_start_lag(ui);
    }
    return std::pair{level, per_start};
  };
  std::vector<double> ss(units.size(), 0.0), sr(units.size(), 0.0);  // per chain start
  for (std::size_t ui = 0; ui < units.size(); ++ui) {
    const Unit& u = units[ui];
    cost.force[ui] = solve_unit(chain, ui, u, w, preds != nullptr ? &(*preds)[ui] : nullptr);
    if (!u.zero_change) continue;
    const auto p = static_cast<std::size_t>(u.prev);
    const auto [level, per_start] = reading(ui);
    const auto [p_level, p_per_start] = reading(p);
    rest[ui] = (u.zero_n - units[p].zero_n) - (level - p_level);
    slope[ui] = per_start - p_per_start;
    const auto c = static_cast<std::size_t>(u.chain);
    ss[c] += slope[ui] * slope[ui];
    sr[c] += slope[ui] * rest[ui];
  }
  // The unknown start lag of each chain: least squares, at least 0 (a load leaves no less).
  for (std::size_t ui = 0; ui < units.size(); ++ui) {
    const Unit& u = units[ui];
    if (!u.zero_change) continue;
    const auto c = static_cast<std::size_t>(u.chain);
    const double start = units[c].unknown_start && ss[c] > 0.0 ? std::max(0.0, sr[c] / ss[c]) : 0.0;
    const double r = rest[ui] - start * slope[ui];
    cost.zero[ui] = r * r;
  }
  return cost;
}

struct Pooled {
  double norm = 0.0;  // sum of frames x peak^2
  long frames = 0;
  double r1 = 0.0;  // lag-1 autocorrelation of the baseline residuals
  double neff_fraction = 1.0;
  int folds = 5;
  std::vector<int> fold_of;  // per unit
  // The zero channel: observed changes, their sum of peak^2, and whether it takes part (it
  // does not when nothing is observed or every change is exactly zero, as in synthetic input).
  long zero_changes = 0;
  double zero_norm = 0.0;
  bool zero_channel = false;
  int unknown_starts = 0;  // chains with an observed change whose start lag is unknown
};

// Shared parameters a candidate adds, with the start lags it solves.
int param_count(const CandidateSpec& spec, const Pooled& p) {
  return static_cast<int>(spec.params.size()) +
         (spec.reads_in_swing && p.zero_channel ? p.unknown_starts : 0);
}

double nrmse(double sse, double norm) {
  return norm > 0 ? 100.0 * std::sqrt(sse / norm) : 0.0;
}

double effective_frames(const Pooled& p) {
  return std::max(2.0, static_cast<double>(p.frames) * p.neff_fraction);
}

// -2 log-likelihood (up to a constant) of the two channels, each with its own residual
// variance: the force residuals' effective sample size and the zero changes' count weigh them.
// The zero channel's residuals are some hundred times smaller than the force's; summing squares
// would let the force decide alone.
double deviance(double force_sse, double zero_sse, const Pooled& p) {
  double d = effective_frames(p) * std::log(std::max(force_sse, 1e-300));
  if (p.zero_channel)
    d += static_cast<double>(p.zero_changes) * std::log(std::max(zero_sse, 1e-300));
  return d;
}

double bic(const Costs& c, const Pooled& p, int params) {
  const double n = static_cast<double>(p.frames);
  const double neff = effective_frames(p);
  double b = neff * std::log(std::max(c.force_sse(), 1e-300) / n);
  double count = neff;
  if (p.zero_channel) {
    const auto z = static_cast<double>(p.zero_changes);
    b += z * std::log(std::max(c.zero_sse(), 1e-300) / z);
    count += z;
  }
  return b + params * std::log(count);
}

struct CandidateOutcome {
  const CandidateSpec* spec = nullptr;
  std::vector<double> theta;      // full data, refined
  std::vector<double> se;         // of theta
  std::vector<double> robust_se;  // of theta, the step-clustered sandwich's
  Costs heldout;                  // per unit, under the parameters fitted on the other folds
  Costs in_sample;                // per unit at theta
};

// Every combination of the parameters' grid values; a parameter in `fixed` takes that value only.
std::vector<std::vector<double>> grid_of(const CandidateSpec& spec,
                                         const std::map<std::string, double>& fixed = {}) {
  std::vector<std::vector<double>> grid{{}};
  for (const ParamSpec& p : spec.params) {
    const auto given = fixed.find(p.name);
    std::vector<std::vector<double>> next;
    for (const auto& partial : grid) {
      for (double v : given != fixed.end() ? std::vector<double>{given->second} : p.grid) {
        auto t = partial;
        t.push_back(v);
        next.push_back(std::move(t));
      }
    }
    grid = std::move(next);
  }
  return grid;
}

// Half the grid's spacing around its point nearest `value`.
double half_local_spacing(const ParamSpec& p, double value) {
  const auto& g = p.grid;
  if (g.size() < 2) return 0.1 * std::abs(value);
  std::size_t i = 0;
  for (std::size_t k = 1; k < g.size(); ++k) {
    if (std::abs(g[k] - value) < std::abs(g[i] - value)) i = k;
  }
  const std::size_t lo = i > 0 ? i - 1 : i;
  const std::size_t hi = i + 1 < g.size() ? i + 1 : i;
  return 0.5 * (g[hi] - g[lo]) / static_cast<double>(hi - lo);
}

// Fits one candidate on top of `base` (fixed effects): grid, k-fold, refinement, SEs.
// Every evaluation of the model first checks `stop`. The candidate goes in at index `place` among
// the base's effects (the end by default), which orders it among those of its own stage.
CandidateOutcome fit_candidate(const std::vector<Unit>& units, const Pooled& pooled,
                               std::span<const FixedEffect> base, const CandidateSpec& spec,
                               const std::stop_token& stop = {},
                               std::size_t place = std::numeric_limits<std::size_t>::max()) {
  const auto check_stop = [&] {
    if (stop.stop_requested()) throw FitStopped();
  };
  std::vector<FixedEffect> made_base(base.begin(), base.end());
  for (FixedEffect& e : made_base) {
    if (e.made == nullptr) e.made = e.spec->make(units, e.theta);
  }
  base = made_base;
  const auto with_candidate = [&](const std::vector<double>& th) {
    std::vector<FixedEffect> fx(base.begin(), base.end());
    fx.insert(fx.begin() + static_cast<std::ptrdiff_t>(std::min(place, fx.size())), {&spec, th});
    return fx;
  };
  const auto grid = grid_of(spec);
  std::vector<Costs> costs(grid.size());
  parallel_for(grid.size(), [&](std::size_t gi) {
    check_stop();
    costs[gi] = unit_costs(units, with_candidate(grid[gi]));
  });
  // The two channels' deviance over the units of every fold but `held_out` (-1: all units).
  const auto deviance_without = [&](const Costs& c, int held_out) {
    double force = 0.0, zero = 0.0;
    for (std::size_t ui = 0; ui < units.size(); ++ui) {
      if (pooled.fold_of[ui] == held_out) continue;
      force += c.force[ui];
      zero += c.zero[ui];
    }
    return deviance(force, zero, pooled);
  };
  const auto costs_at = [&](const std::vector<double>& th) {
    check_stop();
    return unit_costs(units, with_candidate(th));
  };
  // The sandwich's standard errors with the units of one step as a cluster (its regions share the
  // step's loading and swing windows). Each unit's gradient of the deviance is a central
  // difference over one model standard error, where the deviance rises by about 1 and the kinks
  // of the profile (a unit's n moving on its grid) are averaged over; none where the model has
  // none or the difference would leave the box.
  const auto step_clustered_se = [&](const std::vector<double>& theta,
                                     const std::vector<double>& model_se,
                                     const std::vector<double>& model_cov, const auto& costs_of) {
    const std::size_t q = theta.size();
    std::vector<double> none(q, std::numeric_limits<double>::quiet_NaN());
    const Costs at = costs_of(theta);
    const double force_weight = effective_frames(pooled) / std::max(at.force_sse(), 1e-300);
    const double zero_weight = pooled.zero_channel ? static_cast<double>(pooled.zero_changes) /
                                                         std::max(at.zero_sse(), 1e-300)
                                                   : 0.0;
    std::vector<std::vector<double>> gradients(units.size(), std::vector<double>(q));
    for (std::size_t p = 0; p < q; ++p) {
      if (!std::isfinite(model_se[p])) return none;
      std::vector<double> up = theta, down = theta;
      up[p] += model_se[p];
      down[p] -= model_se[p];
      if (up[p] > spec.params[p].hi || down[p] < spec.params[p].lo) return none;
      const Costs cu = costs_of(up);
      const Costs cd = costs_of(down);
      for (std::size_t ui = 0; ui < units.size(); ++ui) {
        gradients[ui][p] = (force_weight * (cu.force[ui] - cd.force[ui]) +
                            zero_weight * (cu.zero[ui] - cd.zero[ui])) /
                           (2 * model_se[p]);
      }
    }
    std::vector<int> step_of(units.size());
    for (std::size_t ui = 0; ui < units.size(); ++ui) step_of[ui] = units[ui].ordinal;
    return clustered_sandwich_se(model_cov, gradients, step_of);
  };
  SearchBox box;
  for (const ParamSpec& p : spec.params) {
    box.lo.push_back(p.lo);
    box.hi.push_back(p.hi);
  }
  // From the grid point that fits the units outside `held_out` best, the pattern search, its
  // steps starting at half the grid's spacing around the start so that a geometric grid (the
  // time constants) is searched at its own scale; on all units (-1) then the settling that
  // gives the standard errors. Returns the parameters, their costs on every unit and the SEs.
  const auto refine = [&](int held_out) {
    std::size_t best = 0;
    for (std::size_t gi = 1; gi < grid.size(); ++gi) {
      if (deviance_without(costs[gi], held_out) < deviance_without(costs[best], held_out)) {
        best = gi;
      }
    }
    // Every point's costs on every unit, kept: the held-out errors and the in-sample costs are
    // those of the point the search ends on.
    std::map<std::vector<double>, Costs> seen{{grid[best], costs[best]}};
    const SearchObjective objective = [&](const std::vector<double>& th) {
      auto it = seen.find(th);
      if (it == seen.end()) it = seen.emplace(th, costs_at(th)).first;
      return deviance_without(it->second, held_out);
    };
    std::vector<double> step(grid[best].size());
    for (std::size_t p = 0; p < step.size(); ++p) {
      step[p] = half_local_spacing(spec.params[p], grid[best][p]);
    }
    SearchPoint at = pattern_search({grid[best], deviance_without(costs[best], held_out)},
                                    std::move(step), box, objective);
    std::vector<double> se, robust_se;
    if (held_out < 0) {
      SettledMinimum settled = settle_on_stencil(std::move(at), box, objective);
      at = std::move(settled.at);
      se = std::move(settled.se);
      robust_se = step_clustered_se(at.theta, se, settled.cov, [&](const std::vector<double>& th) {
        auto it = seen.find(th);
        if (it == seen.end()) it = seen.emplace(th, costs_at(th)).first;
        return it->second;
      });
    }
    return std::tuple{at.theta, seen.at(at.theta), se, robust_se};
  };
  CandidateOutcome out;
  out.spec = &spec;
  out.heldout = {std::vector<double>(units.size(), 0.0), std::vector<double>(units.size(), 0.0)};
  // Each fold's held-out error under the parameters fitted (grid, then refined) on the other
  // folds; and the fit on all steps (the last slot).
  const auto folds = static_cast<std::size_t>(pooled.folds);
  std::vector<std::tuple<std::vector<double>, Costs, std::vector<double>, std::vector<double>>>
      fits(folds + 1);
  parallel_for(fits.size(),
               [&](std::size_t f) { fits[f] = refine(f < folds ? static_cast<int>(f) : -1); });
  for (std::size_t ui = 0; ui < units.size(); ++ui) {
    const Costs& c = std::get<1>(fits[static_cast<std::size_t>(pooled.fold_of[ui])]);
    out.heldout.force[ui] = c.force[ui];
    out.heldout.zero[ui] = c.zero[ui];
  }
  std::tie(out.theta, out.in_sample, out.se, out.robust_se) = std::move(fits[folds]);
  // At a bound the minimum is the constraint's, not the data's: the curvature says nothing of
  // how well the parameter is determined.
  for (std::size_t p = 0; p < out.theta.size(); ++p) {
    if (out.theta[p] <= spec.params[p].lo || out.theta[p] >= spec.params[p].hi) {
      out.se[p] = std::numeric_limits<double>::quiet_NaN();
      out.robust_se[p] = std::numeric_limits<double>::quiet_NaN();
    }
  }
  return out;
}

// Effects are fitted one after another, each on top of those before it, so an earlier one was
// fitted without the later ones: a saturation ceiling fitted before crosstalk takes up the
// neighbours' share of a capped cell (104 bits for 85 at a coupling of 0.08), a hysteresis
// before it the widened footprint (0.43 for 0.2). One round of coordinate descent fits each
// again, in order and in its place in the chain, with all the others in place; it took those to
// 85 bits and 0.21. The round ends on the last effect, held out as in `last`, the outcome of the
// fit one after another, so the two held-out errors hold out the same parameters (in both the
// earlier effects' are fitted on all steps, so the refit, whose earlier effects saw the later
// ones, holds out a little less than it seems); the round is kept where it predicts the held-out
// steps better and no parameter loses the standard error it had one after another, `had_se`, one
// per effect of `chosen` (a second effect that only takes up what the first's form leaves can
// otherwise draw the first off). One that had none, an effect the data do not show listed with
// others (`analyze --effects`), does not hold the others back: a listed creep at its bounds kept a
// ceiling at 104 bits for 85. Returns the refits in the order of `chosen`, whose parameters they
// then replace; none where the round is not kept or there is one effect.
std::vector<CandidateOutcome> refit_together(const std::vector<Unit>& units, const Pooled& pooled,
                                             std::vector<FixedEffect>& chosen,
                                             std::span<const std::vector<double>> had_se,
                                             const CandidateOutcome& last,
                                             const std::stop_token& stop = {}) {
  if (chosen.size() < 2) return {};
  if (had_se.size() != chosen.size()) {
    throw std::logic_error("refit_together: one set of standard errors per effect expected");
  }
  std::vector<FixedEffect> refitted = chosen;
  std::vector<CandidateOutcome> refits;
  for (std::size_t i = 0; i < refitted.size(); ++i) {
    std::vector<FixedEffect> others;
    for (std::size_t j = 0; j < refitted.size(); ++j) {
      if (j != i) others.push_back({refitted[j].spec, refitted[j].theta});
    }
    refits.push_back(fit_candidate(units, pooled, others, *refitted[i].spec, stop, i));
    refitted[i] = {refits.back().spec, refits.back().theta};
  }
  const auto heldout_deviance = [&](const CandidateOutcome& c) {
    return deviance(c.heldout.force_sse(), c.heldout.zero_sse(), pooled);
  };
  bool determined = true;
  for (std::size_t i = 0; i < refits.size(); ++i) {
    for (std::size_t p = 0; p < refits[i].se.size(); ++p) {
      const bool had = p < had_se[i].size() && std::isfinite(had_se[i][p]);
      determined = determined && (!had || std::isfinite(refits[i].se[p]));
    }
  }
  if (!determined || !(heldout_deviance(refits.back()) < heldout_deviance(last))) return {};
  chosen = std::move(refitted);
  return refits;
}

// ---- preparation ------------------------------------------------------------------------------

// The unit's area and what the correction took off its force at each coupling the steps were
// measured again at, and what its cells read of other regions' cells there (Unit::crosstalk). A
// frame whose footprint the corrected readings leave undetermined (the fits over the cells with and
// without the threshold disagree) takes the unit's own area times the corrected over the own area
// of the nearest frame that has both: left at 0, the model would have no force there. None where a
// coupling's area is another source's (the contact ellipse instead of the footprint).
void crosstalk_series(const DiscrepancyStep& ds, const RegionAnalysis& ra,
                      std::span<const std::size_t> frames, Unit& u) {
  if (ds.crosstalk.size() != discrepancy_detail::kCrosstalkGrid.size()) return;
  const auto r = index_of(u.region);
  const std::size_t n = frames.size();
  std::vector<std::vector<double>> areas(ds.crosstalk.size()), removed(ds.crosstalk.size()),
      spill(ds.crosstalk.size());
  std::vector<double> ratio(n);
  for (std::size_t g = 0; g < ds.crosstalk.size(); ++g) {
    const CrosstalkView& v = ds.crosstalk[g];
    if (v.source[r] != ra.area || v.area_mm2[r].size() != ra.series.t_s.size() ||
        v.force_n[r].size() != ra.series.t_s.size() ||
        v.spill_in_n[r].size() != ra.series.t_s.size()) {
      return;
    }
    std::vector<double>& a = areas[g];
    for (std::size_t k = 0; k < n; ++k) {
      a.push_back(v.area_mm2[r][frames[k]]);
      removed[g].push_back(u.y[k] - v.force_n[r][frames[k]]);
      spill[g].push_back(v.spill_in_n[r][frames[k]]);
    }
    std::fill(ratio.begin(), ratio.end(), std::numeric_limits<double>::quiet_NaN());
    for (std::size_t k = 0; k < n; ++k) {
      if (a[k] > 0.0 && u.area[k] > 0.0) ratio[k] = a[k] / u.area[k];
    }
    discrepancy_detail::fill_from_nearest(ratio, std::numeric_limits<double>::quiet_NaN());
    for (std::size_t k = 0; k < n; ++k) {
      if (!(u.area[k] > 0.0) || a[k] > 0.0) continue;
      if (std::isnan(ratio[k])) return;
      a[k] = ratio[k] * u.area[k];
    }
  }
  u.crosstalk = std::make_shared<const discrepancy_detail::CrosstalkSeries>(
      discrepancy_detail::CrosstalkSeries{std::move(areas), std::move(removed), std::move(spill)});
}

struct Prepared {
  std::vector<Unit> units;
  Pooled pooled;
  int steps = 0;
  int left_out = 0;  // region-steps fitted on the contact ellipse while others had a footprint
  std::vector<std::pair<Foot, int>> step_ids;  // by ordinal
};

Prepared prepare(const DiscrepancyInput& input, int folds) {
  Prepared out;
  std::vector<std::size_t> order(input.steps.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    const auto& x = input.steps[a].analysis;
    const auto& y = input.steps[b].analysis;
    if (x.t_heel_strike_s != y.t_heel_strike_s) return x.t_heel_strike_s < y.t_heel_strike_s;
    return x.foot < y.foot;
  });
  std::array<std::array<int, kRegionCount>, 2> last{};
  for (auto& f : last) f.fill(-1);
  const double dt = 1.0 / input.sample_rate_hz;
  // A contact ellipse moves in whole cells; its misfit (toes: 20-30 % NRMSE) would swamp the
  // effects sought, so where the session has footprints only they are compared.
  bool footprints = false;
  for (const DiscrepancyStep& ds : input.steps) {
    for (const RegionAnalysis& ra : ds.analysis.regions) {
      footprints = footprints || (ra.fit.status == FitStatus::Ok && ra.area != AreaSource::Ellipse);
    }
  }
  for (std::size_t o = 0; o < order.size(); ++o) {
    const DiscrepancyStep& ds = input.steps[order[o]];
    const StepAnalysis& sa = ds.analysis;
    out.step_ids.emplace_back(sa.foot, sa.step);
    const double stance = std::max(dt, sa.t_toe_off_s - sa.t_heel_strike_s);
    for (Region region : kRegions) {
      const RegionAnalysis& ra = sa.at(region);
      if (ra.fit.status != FitStatus::Ok || ra.frames < kMinContactFrames) continue;
      if (ra.series.t_s.empty() || !(ra.peak_force_n > 0.0)) continue;
      if (footprints && ra.area == AreaSource::Ellipse) {
        ++out.left_out;
        continue;
      }
      Unit u;
      u.ordinal = static_cast<int>(o);
      u.t_contact_s = ra.t_contact_s;
      u.foot = sa.foot;
      u.step = sa.step;
      u.region = region;
      // The frames the tissue fit was given: without a measured area the model has nothing to
      // say. And at the heel, the stance frames before the first of them in which it already
      // reads a load: a heel strike with a few cells, whose area the cells do not give, where
      // the model expects next to nothing. They are kept only where some of them carry more
      // than the first frame with an area, a pulse ahead of the loading: a light walker's heel
      // takes its load too gently for its cells to give a footprint (at 25 kg up to 171 N before
      // the first), and a load that only rises into that frame is no impact.
      std::vector<std::size_t> frames;
      for (std::size_t i = 0; i < ra.series.t_s.size(); ++i) {
        if (ra.series.area_mm2[i] > 0.0) {
          frames.push_back(i);
        } else if (region == Region::Heel && frames.empty() && ra.series.force_n[i] > 0.0) {
          frames.push_back(i);
        }
      }
      const auto first_area = std::find_if(
          frames.begin(), frames.end(), [&](std::size_t i) { return ra.series.area_mm2[i] > 0.0; });
      if (first_area != frames.begin()) {
        double before = 0.0;
        for (auto it = frames.begin(); it != first_area; ++it) {
          before = std::max(before, ra.series.force_n[*it]);
        }
        const bool pulse = first_area != frames.end() && before > ra.series.force_n[*first_area];
        if (!pulse) frames.erase(frames.begin(), first_area);
      }
      RegionSeries contact;
      for (std::size_t i : frames) {
        contact.t_s.push_back(ra.series.t_s[i]);
        contact.area_mm2.push_back(ra.series.area_mm2[i]);
        contact.force_n.push_back(ra.series.force_n[i]);
      }
      if (!contact.t_s.empty() && !(contact.area_mm2.front() > 0.0)) {
        u.t_contact_s = std::min(u.t_contact_s, contact.t_s.front());
      }
      if (contact.t_s.size() < static_cast<std::size_t>(kMinContactFrames)) continue;
      u.series_frames = frames;
      u.t = contact.t_s;
      u.y = contact.force_n;
      u.area = contact.area_mm2;
      u.dt_s = dt;
      u.peak_n = *std::max_element(u.y.begin(), u.y.end());
      if (!(u.peak_n > 0.0)) continue;
      const EllipsoidParams p = ra.fit.params();
      const IdentifiableParams id = identifiable(p);
      u.shape_model = {id, p.C_mm, input.model};
      {
        discrepancy_detail::Shapes sh = discrepancy_detail::shapes_of(u.t, u.area, u.shape_model);
        u.E = sh.En.front();
        u.En = std::move(sh.En);
        u.V = std::move(sh.V);
        u.d_mm = std::move(sh.d_mm);
        u.ddot_mm_per_s = std::move(sh.ddot_mm_per_s);
      }
      std::tie(u.K0, u.D0) = nnls2(u.y, u.E, u.V);
      const std::size_t n = u.t.size();
      u.phase.resize(n);
      for (std::size_t i = 0; i < n; ++i) {
        u.phase[i] = std::clamp((u.t[i] - sa.t_heel_strike_s) / stance, 0.0, 1.0);
      }
      crosstalk_series(ds, ra, frames, u);
      u.sat.assign(n, 0.0);
      const auto& sat = ds.saturated_cells[index_of(region)];
      for (std::size_t k = 0; k < n; ++k) {
        if (frames[k] < sat.size()) u.sat[k] = sat[frames[k]];
      }
      // Noise floor: the force's own noise about a smooth fit, and the force the model moves
      // when the measured area moves by one cell's quantisation (cell area / sqrt 12).
      const double meas_sd = savgol_noise_sd(u.y);
      u.floor2.assign(n, meas_sd * meas_sd);
      for (std::size_t i = 0; i < n; ++i) {
        if (!(u.area[i] > 0.0)) continue;
        const double a = std::min(u.area[i] / id.P_mm2, kMaxAreaFraction);
        const double g = 1.0 - std::sqrt(1.0 - a);
        const double dE_dg = id.P_mm2 * ((2.0 + id.n) * std::pow(g, 1.0 + id.n) * (1.0 - g / 3.0) -
                                         std::pow(g, 2.0 + id.n) / 3.0);
        const double dg_dA = 1.0 / (2.0 * std::sqrt(1.0 - a) * id.P_mm2);
        const double q = u.K0 * dE_dg * dg_dA * input.cell_area_mm2 / std::sqrt(12.0);
        u.floor2[i] += q * q;
      }
      u.zero_n = ds.region_zero_n[index_of(region)];
      u.cells = input.region_cells[index_of(region)];
      u.t_pre_zero_s = ds.pre_zero_t_s;
      u.t_post_zero_s = ds.post_zero_t_s;
      int& prev = last[static_cast<std::size_t>(sa.foot)][index_of(region)];
      u.prev = prev;
      if (std::isfinite(u.t_pre_zero_s) && std::isfinite(u.t_post_zero_s)) {
        const auto self = static_cast<int>(out.units.size());
        const Unit* p = prev >= 0 ? &out.units[static_cast<std::size_t>(prev)] : nullptr;
        u.zero_change = p != nullptr && p->chain >= 0 && p->step + 1 == u.step;
        u.chain = u.zero_change ? p->chain : self;
        u.unknown_start = !u.zero_change && u.step != 0;
      }
      prev = static_cast<int>(out.units.size());
      out.units.push_back(std::move(u));
    }
  }
  out.steps = static_cast<int>(order.size());
  {
    Workspace w;
    for (std::size_t ui = 0; ui < out.units.size(); ++ui) {
      Unit& u = out.units[ui];
      u.base_sse = solve_unit({}, ui, u, w, &u.base_pred, true);
    }
  }
  Pooled& p = out.pooled;
  p.folds = folds;
  double zero_sse = 0.0;
  for (const Unit& u : out.units) {
    p.norm += u.norm();
    p.frames += static_cast<long>(u.y.size());
    p.fold_of.push_back(u.ordinal % folds);
    if (!u.zero_change) continue;
    const Unit& start = out.units[static_cast<std::size_t>(u.chain)];
    if (start.unknown_start && u.prev == u.chain) ++p.unknown_starts;
    const double dz = u.zero_n - out.units[static_cast<std::size_t>(u.prev)].zero_n;
    zero_sse += dz * dz;
    ++p.zero_changes;
    p.zero_norm += u.peak_n * u.peak_n;
  }
  p.zero_channel = p.zero_changes > 0 && zero_sse > 0.0;
  // Lag-1 autocorrelation of the baseline residuals, within units.
  double c0 = 0, c1 = 0;
  for (const Unit& u : out.units) {
    double prev = 0;
    for (std::size_t i = 0; i < u.y.size(); ++i) {
      const double r = u.y[i] - u.base_pred[i];
      c0 += r * r;
      if (i > 0) c1 += r * prev;
      prev = r;
    }
  }
  p.r1 = c0 > 0 ? std::clamp(c1 / c0, -0.99, 0.99) : 0.0;
  p.neff_fraction = std::max(0.0, p.r1) > 0 ? (1 - p.r1) / (1 + p.r1) : 1.0;
  return out;
}

// ---- comparisons -----------------------------------------------------------------------------

std::vector<RegionComparison> compare_regions(const std::vector<Unit>& units,
                                              std::span<const double> before,
                                              std::span<const double> after) {
  std::vector<RegionComparison> out;
  for (Region region : kRegions) {
    RegionComparison c;
    c.region = region;
    double b = 0, a = 0, norm = 0;
    for (std::size_t ui = 0; ui < units.size(); ++ui) {
      if (units[ui].region != region) continue;
      ++c.step_regions;
      b += before[ui];
      a += after[ui];
      norm += units[ui].norm();
    }
    c.baseline_heldout_nrmse_pct = nrmse(b, norm);
    c.extended_heldout_nrmse_pct = nrmse(a, norm);
    out.push_back(c);
  }
  return out;
}

EffectEstimate estimate_of(const CandidateOutcome& c) {
  EffectEstimate e;
  e.name = c.spec->name;
  for (std::size_t p = 0; p < c.theta.size(); ++p) {
    e.params.push_back({c.spec->params[p].name, c.theta[p], c.se[p], c.robust_se[p]});
  }
  return e;
}

bool named_in(const std::vector<EffectEstimate>& named, std::string_view name) {
  return std::any_of(named.begin(), named.end(),
                     [&](const EffectEstimate& e) { return e.name == name; });
}

double shrink(double before, double after) {
  return before > 0.0 ? 100.0 * (1.0 - after / before) : 0.0;
}

// One candidate against the model it extends (`base`: its held-out and in-sample costs).
CandidateResult result_of(const CandidateOutcome& c, const Pooled& pooled,
                          const CandidateOutcome& base, int base_params) {
  CandidateResult r;
  r.name = c.spec->name;
  r.params = estimate_of(c).params;
  r.in_sample_nrmse_pct = nrmse(c.in_sample.force_sse(), pooled.norm);
  r.heldout_nrmse_pct = nrmse(c.heldout.force_sse(), pooled.norm);
  r.shrink_pct = shrink(nrmse(base.heldout.force_sse(), pooled.norm), r.heldout_nrmse_pct);
  r.zero_heldout_nrmse_pct = nrmse(c.heldout.zero_sse(), pooled.zero_norm);
  r.zero_shrink_pct =
      shrink(nrmse(base.heldout.zero_sse(), pooled.zero_norm), r.zero_heldout_nrmse_pct);
  r.heldout_deviance_drop = deviance(base.heldout.force_sse(), base.heldout.zero_sse(), pooled) -
                            deviance(c.heldout.force_sse(), c.heldout.zero_sse(), pooled);
  const int params = base_params + param_count(*c.spec, pooled);
  r.bic = bic(c.in_sample, pooled, params);
  r.delta_bic = r.bic - bic(base.in_sample, pooled, base_params);
  return r;
}

const CandidateSpec& spec_named(const std::vector<CandidateSpec>& specs, std::string_view name) {
  for (const CandidateSpec& s : specs) {
    if (s.name == name) return s;
  }
  check_discrepancy_effect(name);
  throw std::logic_error("candidate list and names disagree");
}

void check_settings(const DiscrepancySettings& s, const DiscrepancyInput& input) {
  if (s.folds < 2) throw std::invalid_argument("discrepancy: folds must be >= 2");
  if (s.phase_bins < 10) throw std::invalid_argument("discrepancy: phase_bins must be >= 10");
  if (!(input.sample_rate_hz > 0) || !(input.cell_area_mm2 > 0) || !(input.newtons_per_bit > 0)) {
    throw std::invalid_argument("discrepancy: sample rate, cell area and N/bit must be > 0");
  }
  if (s.min_ceiling_steps < 0 || !(s.min_ceiling_steps_pct >= 0.0)) {
    throw std::invalid_argument("discrepancy: the ceiling's step counts must be >= 0");
  }
  if (!std::isfinite(s.min_neighbour_share)) {
    throw std::invalid_argument("discrepancy: min_neighbour_share must be finite");
  }
  if (!std::isfinite(s.min_cell_coupling)) {
    throw std::invalid_argument("discrepancy: min_cell_coupling must be finite");
  }
  if (static_cast<int>(input.steps.size()) < s.folds) {
    throw std::invalid_argument("discrepancy: " + std::to_string(input.steps.size()) +
                                " complete steps, need at least " + std::to_string(s.folds) +
                                " (one per fold)");
  }
}

// Steps in which two or more cells of one region read at the session's top in one frame, or -1
// where no step has cell counts (input not made from cells).
int ceiling_plateau_steps(const DiscrepancyInput& input) {
  int known = 0, plateau = 0;
  for (const DiscrepancyStep& ds : input.steps) {
    bool counted = false, seen = false;
    for (const std::vector<int>& counts : ds.saturated_cells) {
      counted = counted || !counts.empty();
      seen = seen || std::any_of(counts.begin(), counts.end(), [](int n) { return n >= 2; });
    }
    known += counted ? 1 : 0;
    plateau += seen ? 1 : 0;
  }
  return known > 0 ? plateau : -1;
}

}  // namespace

std::vector<std::string_view> discrepancy_effect_names() {
  return {"stress_relaxation", "hysteresis",    "impact_transient", "sensor_saturation",
          "sensor_creep",      "thermal_drift", kCrosstalk};
}

namespace {

bool names_crosstalk(std::span<const std::string> effects) {
  return std::find(effects.begin(), effects.end(), kCrosstalk) != effects.end();
}

void check_crosstalk_views(const DiscrepancyInput& input, std::span<const std::string> effects) {
  if (!names_crosstalk(effects)) return;
  if (std::any_of(input.steps.begin(), input.steps.end(),
                  [](const DiscrepancyStep& s) { return s.crosstalk.empty(); })) {
    throw std::invalid_argument(
        "crosstalk needs every step measured again at its couplings (measure_crosstalk_views)");
  }
}

}  // namespace

void check_discrepancy_effect(std::string_view name) {
  std::string known;
  for (std::string_view n : discrepancy_effect_names()) {
    if (n == name) return;
    known += (known.empty() ? "" : ", ") + std::string(n);
  }
  throw std::invalid_argument("unknown effect '" + std::string(name) + "' (known: " + known + ")");
}

std::vector<ZeroLevelDrift> zero_level_drift(const DiscrepancyInput& input) {
  std::vector<ZeroLevelDrift> out;
  for (Foot foot : {Foot::Left, Foot::Right}) {
    std::vector<const DiscrepancyStep*> steps;
    for (const DiscrepancyStep& s : input.steps) {
      if (s.analysis.foot == foot) steps.push_back(&s);
    }
    if (steps.size() < 3) continue;
    std::sort(steps.begin(), steps.end(), [](const DiscrepancyStep* a, const DiscrepancyStep* b) {
      return a->analysis.t_heel_strike_s < b->analysis.t_heel_strike_s;
    });
    ZeroLevelDrift z;
    z.foot = foot;
    z.steps = static_cast<int>(steps.size());
    z.first_bits = steps.front()->zero_bits;
    z.last_bits = steps.back()->zero_bits;
    std::vector<double> changes, peaks;
    z.lowest_bits = z.highest_bits = z.first_bits;
    for (std::size_t i = 0; i < steps.size(); ++i) {
      z.lowest_bits = std::min(z.lowest_bits, steps[i]->zero_bits);
      z.highest_bits = std::max(z.highest_bits, steps[i]->zero_bits);
      peaks.push_back(steps[i]->peak_summed_bits);
      z.t_s.push_back(steps[i]->analysis.t_heel_strike_s);
      z.zero_bits.push_back(steps[i]->zero_bits);
      if (i > 0) changes.push_back(std::abs(steps[i]->zero_bits - steps[i - 1]->zero_bits));
    }
    z.scatter_bits = 1.4826 * spread_of(std::move(changes)).median / std::sqrt(2.0);
    const double range = z.highest_bits - z.lowest_bits;
    const double peak = spread_of(std::move(peaks)).median;
    z.range_pct_of_peak = peak > 0.0 ? 100.0 * range / peak : 0.0;
    z.drifting = range > kZeroDriftScatters * std::max(z.scatter_bits, 1.0) &&
                 z.range_pct_of_peak >= kZeroDriftPctOfPeak;
    out.push_back(z);
  }
  return out;
}

AnalysisSettings discrepancy_analysis_settings() {
  AnalysisSettings settings;
  settings.fit.smoothing = Smoothing::None;
  return settings;
}

DiscrepancyInput prepare_discrepancy_input(std::span<const Step> steps, const InsoleLayout& layout,
                                           const Config& config, const AnalysisSettings& settings) {
  std::vector<Step> ok;
  for (const Step& s : steps) {
    if (s.status == StepStatus::Ok && !s.stance.empty()) ok.push_back(s);
  }
  DiscrepancyInput input =
      make_discrepancy_input(ok, analyse_steps(ok, layout, config, settings), layout, config);
  measure_crosstalk_views(input, ok, layout, config, settings.area);
  return input;
}

namespace {

// What a cell reads of its edge neighbours' readings where they read kNeighbourShareBits or
// more together: its 1st percentile over every such cell and stance frame (zeroed readings,
// before the threshold). A cell wholly outside a contact reads nothing without crosstalk and
// its share of its neighbours' with it.
NeighbourShare neighbour_share(std::span<const Step> steps, const InsoleLayout& layout) {
  std::vector<double> shares;
  std::vector<double> r(layout.sensor_count());
  for (const Step& s : steps) {
    if (s.sensor_zero_bits.size() != r.size()) continue;
    for (const Frame& f : s.stance) {
      if (f.bits.size() != r.size()) continue;
      for (std::size_t c = 0; c < r.size(); ++c) {
        r[c] = static_cast<double>(f.bits[c]) - s.sensor_zero_bits[c];
      }
      for (std::size_t c = 0; c < r.size(); ++c) {
        double around = 0.0;
        for (const Neighbour& n : layout.neighbours(c)) around += n.shared_edge * r[n.sensor];
        if (around >= kNeighbourShareBits) shares.push_back(r[c] / around);
      }
    }
  }
  NeighbourShare out;
  out.cell_frames = static_cast<long>(shares.size());
  if (shares.empty()) return out;
  const auto k = static_cast<std::size_t>(0.01 * static_cast<double>(shares.size() - 1));
  std::nth_element(shares.begin(), shares.begin() + static_cast<std::ptrdiff_t>(k), shares.end());
  out.floor = shares[k];
  return out;
}

}  // namespace

DiscrepancyInput extended_model_input(std::span<const Step> steps,
                                      std::vector<StepAnalysis> analyses,
                                      const InsoleLayout& layout, const Config& config,
                                      std::span<const std::string> effects, AreaSource area) {
  DiscrepancyInput input = make_discrepancy_input(steps, std::move(analyses), layout, config);
  if (names_crosstalk(effects)) measure_crosstalk_views(input, steps, layout, config, area);
  return input;
}

void measure_crosstalk_views(DiscrepancyInput& input, std::span<const Step> steps,
                             const InsoleLayout& layout, const Config& config, AreaSource area) {
  if (steps.size() != input.steps.size()) {
    throw std::invalid_argument("measure_crosstalk_views: one step per analysed step expected");
  }
  input.neighbour_share = neighbour_share(steps, layout);
  const CellReadingEvidence cells = cell_reading_evidence(steps, layout);
  input.cell_coupling = {cells.coupling(), cells.fits().frames};
  std::vector<CrosstalkCorrection> corrections;
  for (double k : discrepancy_detail::kCrosstalkGrid) corrections.emplace_back(layout, k);
  const CellMeanFootprint cell_mean =
      area == AreaSource::FootprintMean ? CellMeanFootprint::Fit : CellMeanFootprint::Skip;
  parallel_for(steps.size(), [&](std::size_t i) {
    ContactEllipseCache cache;
    std::vector<CrosstalkView>& views = input.steps[i].crosstalk;
    views.assign(corrections.size(), {});
    for (std::size_t g = 0; g < corrections.size(); ++g) {
      const StanceSeries stance =
          measure_stance(steps[i], layout, config.calibration, &cache, cell_mean, &corrections[g]);
      CrosstalkView& v = views[g];
      v.coupling = corrections[g].coupling();
      for (Region region : kRegions) {
        const auto r = index_of(region);
        std::tie(v.area_mm2[r], v.source[r]) = fit_areas_mm2(stance, region, area);
        v.force_n[r].resize(stance.size());
        v.spill_in_n[r].resize(stance.size());
        for (std::size_t f = 0; f < stance.size(); ++f) {
          v.force_n[r][f] = stance.at(f, region).force_n;
          v.spill_in_n[r][f] = stance.at(f, region).spill_in_n;
        }
      }
    }
  });
}

DiscrepancyInput make_discrepancy_input(std::span<const Step> steps,
                                        std::vector<StepAnalysis> analyses,
                                        const InsoleLayout& layout, const Config& config) {
  if (steps.size() != analyses.size()) {
    throw std::invalid_argument("make_discrepancy_input: one analysis per step expected");
  }
  DiscrepancyInput input;
  if (!analyses.empty()) input.model = analyses.front().model;
  for (const StepAnalysis& a : analyses) {
    if (a.model != input.model) {
      throw std::invalid_argument("make_discrepancy_input: steps fitted with different models");
    }
  }
  input.sample_rate_hz = config.sample_rate_hz;
  input.cell_area_mm2 = config.sensor.area_mm2();
  input.newtons_per_bit = config.calibration.newtons_per_bit(config.sensor.area_mm2());
  for (Region region : kRegions) {
    input.region_cells[index_of(region)] = static_cast<int>(layout.region_sensors(region).size());
  }
  input.steps.resize(steps.size());
  for (std::size_t i = 0; i < steps.size(); ++i) {
    input.steps[i].analysis = std::move(analyses[i]);
    DiscrepancyStep& ds = input.steps[i];
    ds.zero_bits = steps[i].bias_bits;
    ds.peak_summed_bits = steps[i].max_summed_bits;
    ds.pre_zero_t_s = steps[i].pre_zero_t_s;
    ds.post_zero_t_s = steps[i].post_zero_t_s;
    for (Region region : kRegions) {
      double bits = 0.0;
      for (std::size_t c : layout.region_sensors(region)) {
        if (c < steps[i].sensor_zero_bits.size()) bits += steps[i].sensor_zero_bits[c];
      }
      ds.region_zero_n[index_of(region)] = bits * input.newtons_per_bit;
    }
  }
  double highest = 0.0;
  for (const Step& s : steps) {
    for (const Frame& f : s.stance) {
      for (std::size_t c = 0; c < f.bits.size() && c < s.sensor_zero_bits.size(); ++c) {
        highest = std::max(highest, f.bits[c] - s.sensor_zero_bits[c]);
      }
    }
  }
  for (std::size_t i = 0; i < steps.size(); ++i) {
    const Step& s = steps[i];
    for (Region region : kRegions) {
      auto& counts = input.steps[i].saturated_cells[index_of(region)];
      for (const Frame& f : s.stance) {
        int n = 0;
        for (std::size_t c : layout.region_sensors(region)) {
          if (c < f.bits.size() && c < s.sensor_zero_bits.size() &&
              f.bits[c] - s.sensor_zero_bits[c] >= highest - kSaturationBandBits) {
            ++n;
          }
        }
        counts.push_back(n);
      }
    }
  }
  return input;
}

namespace {

// find_discrepancy without the candidate `left_out` (none if empty): an effect already undone in
// the readings is no candidate on them.
DiscrepancyResult discrepancy_without(const DiscrepancyInput& input,
                                      const DiscrepancySettings& settings,
                                      const std::function<void(double)>& on_progress,
                                      std::string_view left_out) {
  check_settings(settings, input);
  const Prepared prep = prepare(input, settings.folds);
  const std::vector<Unit>& units = prep.units;
  const Pooled& pooled = prep.pooled;
  auto specs = candidate_specs(input.cell_area_mm2, input.newtons_per_bit);
  std::erase_if(specs, [&](const CandidateSpec& spec) { return spec.name == left_out; });
  const int base_params = 2 * static_cast<int>(units.size());

  DiscrepancyResult out;
  out.steps = prep.steps;
  out.step_regions = static_cast<int>(units.size());
  out.step_regions_left_out = prep.left_out;
  out.frames = pooled.frames;
  double floor_sum = 0;
  for (const Unit& u : units) floor_sum += sum(u.floor2);
  out.noise_floor_nrmse_pct = nrmse(floor_sum, pooled.norm);
  out.nrmse_scale_n =
      pooled.frames > 0 ? std::sqrt(pooled.norm / static_cast<double>(pooled.frames)) : 0.0;

  std::vector<std::vector<double>> base_preds;
  CandidateOutcome baseline;
  baseline.in_sample = unit_costs(units, {}, &base_preds);
  baseline.heldout = baseline.in_sample;  // nothing shared to hold out
  const std::vector<double>& base = baseline.in_sample.force;
  out.baseline_in_sample_nrmse_pct = nrmse(baseline.in_sample.force_sse(), pooled.norm);
  out.baseline_heldout_nrmse_pct = out.baseline_in_sample_nrmse_pct;
  out.baseline_bic = bic(baseline.in_sample, pooled, base_params);
  out.zero_changes = pooled.zero_channel ? pooled.zero_changes : 0;
  out.zero_baseline_heldout_nrmse_pct = nrmse(baseline.heldout.zero_sse(), pooled.zero_norm);
  out.map_before = residual_map(units, base_preds, settings.phase_bins);
  out.diagnostics = diagnose(units, base_preds, settings.phase_bins);
  out.diagnostics.lag1_autocorrelation = pooled.r1;
  out.diagnostics.effective_sample_fraction = pooled.neff_fraction;
  out.zero_levels = zero_level_drift(input);
  out.ceiling_plateau_steps = ceiling_plateau_steps(input);
  out.neighbour_share = input.neighbour_share;
  out.cell_coupling = input.cell_coupling;
  // Too few cells beside a load to judge the share, and the readings do not show crosstalk.
  const bool share_shows_crosstalk =
      input.neighbour_share.cell_frames >= kMinNeighbourShareCellFrames &&
      input.neighbour_share.floor >= settings.min_neighbour_share;
  const CellCoupling& cell_coupling = input.cell_coupling;
  const bool cells_show_crosstalk =
      cell_coupling.frames < 0 ||
      (cell_coupling.frames > 0 && cell_coupling.coupling >= settings.min_cell_coupling);
  const bool ceiling_seen =
      out.ceiling_plateau_steps < 0 ||
      (out.ceiling_plateau_steps >= settings.min_ceiling_steps &&
       out.ceiling_plateau_steps >=
           1e-2 * settings.min_ceiling_steps_pct * static_cast<double>(input.steps.size()));

  // A second round, if the first names an effect, fits one candidate fewer.
  const double rounds = settings.second_effect ? 2.0 : 1.0;
  const auto report = [&](double fraction) {
    if (on_progress) on_progress(std::min(1.0, fraction));
  };
  std::vector<CandidateOutcome> outcomes;
  for (const CandidateSpec& spec : specs) {
    outcomes.push_back(fit_candidate(units, pooled, {}, spec));
    out.candidates.push_back(result_of(outcomes.back(), pooled, baseline, base_params));
    report(static_cast<double>(outcomes.size()) / static_cast<double>(specs.size()) / rounds);
  }
  // A candidate is named when it shrinks the held-out error of the force or of the zero clearly
  // (a creeping sensor shows in the zero only: the zeroing takes it off the stance) and BIC
  // agrees. Of those, the one whose held-out likelihood gains most over both channels.
  // Its parameters must be determined, too: an optimum on a bound of the plausible range or
  // along a flat direction (no finite standard error) is not an effect the data show. And a
  // ceiling or crosstalk must show in the readings themselves (ceiling_seen,
  // share_shows_crosstalk and cells_show_crosstalk).
  // Why a candidate is not named, in words; empty where it is.
  const auto verdict = [&](const CandidateResult& r) {
    std::vector<std::string> reasons;
    if (r.shrink_pct < settings.min_shrink_pct &&
        !(pooled.zero_channel && r.zero_shrink_pct >= settings.min_zero_shrink_pct)) {
      reasons.push_back(fmt::format(
          "its held-out gain ({:.1f} %, {:.1f} % on the zero channel) is under the {:g} % ({:g} %) "
          "needed",
          r.shrink_pct, r.zero_shrink_pct, settings.min_shrink_pct, settings.min_zero_shrink_pct));
    }
    if (r.delta_bic > -settings.min_delta_bic) {
      reasons.push_back(fmt::format("BIC changes by {:+.0f}, where a fall of {:g} is needed",
                                    r.delta_bic, settings.min_delta_bic));
    }
    std::vector<std::string> undetermined;
    for (const ParamEstimate& p : r.params) {
      if (!std::isfinite(p.se)) undetermined.push_back(p.name);
    }
    if (!undetermined.empty()) {
      reasons.push_back(fmt::format(
          "{} {} no standard error (at a bound of its range or along a flat direction: not "
          "determined by the data)",
          fmt::join(undetermined, " and "), undetermined.size() == 1 ? "has" : "have"));
    }
    if (spec_named(specs, r.name).needs_ceiling && !ceiling_seen) {
      reasons.push_back("the readings show no ceiling");
    }
    if (r.name == kCrosstalk && !share_shows_crosstalk) {
      const NeighbourShare& share = input.neighbour_share;
      reasons.push_back(
          share.cell_frames < kMinNeighbourShareCellFrames
              ? fmt::format("too few cells next to loaded ones ({} cell-frames, {} needed) for "
                            "the readings to show crosstalk",
                            share.cell_frames, kMinNeighbourShareCellFrames)
              : fmt::format("the readings show no crosstalk (1 % of the cells next to loaded ones "
                            "read under {:.2g} of their neighbours' readings, where {:g} is "
                            "needed)",
                            share.floor, settings.min_neighbour_share));
    } else if (r.name == kCrosstalk && !cells_show_crosstalk) {
      reasons.push_back(
          cell_coupling.frames == 0
              ? fmt::format("no region-frame has {} cells over the threshold for the cells to "
                            "show crosstalk",
                            CellReadingEvidence::kMinEvidenceCells)
              : fmt::format("the cells show no crosstalk (their readings fit their caps best "
                            "with a coupling of {:.3f} undone, where {:g} is needed)",
                            cell_coupling.coupling, settings.min_cell_coupling));
    }
    return fmt::format("{}", fmt::join(reasons, "; "));
  };
  // The most likely candidate overall, or among those that pass (none if none does). Not only
  // the most likely overall may be named: on a long session the force's many frames make a
  // gain of a few tenths of a per cent in it outweigh a zero channel that a drift halves (a
  // 60-s session of a warming insole: saturation's 3.3 % without a ceiling against the drift's
  // 41 %), and the thresholds hold for every candidate, not only for the most likely one.
  const auto most_likely = [&](const std::vector<CandidateResult>& results, bool passing) {
    std::optional<std::size_t> best;
    for (std::size_t i = 0; i < results.size(); ++i) {
      if (passing && !verdict(results[i]).empty()) continue;
      if (!best || results[i].heldout_deviance_drop > results[*best].heldout_deviance_drop)
        best = i;
    }
    return best;
  };
  const std::size_t overall = most_likely(out.candidates, false).value();
  const std::optional<std::size_t> best = most_likely(out.candidates, true);
  const CandidateOutcome* last = &baseline;
  std::vector<FixedEffect> chosen;
  std::vector<CandidateOutcome> seconds, refits;
  out.most_likely_candidate = out.candidates[overall].name;
  out.not_named_reason = verdict(out.candidates[overall]);
  if (best) {
    const CandidateOutcome& first = outcomes[*best];
    out.named_effects.push_back(estimate_of(first));
    chosen.push_back({first.spec, first.theta});
    last = &first;
    if (settings.second_effect) {
      // A second candidate runs on top of the first at its all-steps parameters, held-out fold
      // or not, so it is compared with the first at those parameters: against the first's
      // fold-by-fold error it would gain what the first loses by being held out.
      CandidateOutcome first_fixed = first;
      first_fixed.heldout = first.in_sample;
      for (const CandidateSpec& spec : specs) {
        if (spec.name == first.spec->name) continue;
        seconds.push_back(fit_candidate(units, pooled, chosen, spec));
        out.second_candidates.push_back(result_of(seconds.back(), pooled, first_fixed,
                                                  base_params + param_count(*first.spec, pooled)));
        // The second round: the other candidates, then the two named fitted once more.
        report((1.0 + static_cast<double>(seconds.size()) / static_cast<double>(specs.size() + 1)) /
               rounds);
      }
      if (const auto b2 = most_likely(out.second_candidates, true)) {
        out.named_effects.push_back(estimate_of(seconds[*b2]));
        chosen.push_back({seconds[*b2].spec, seconds[*b2].theta});
        last = &seconds[*b2];
        refits = refit_together(units, pooled, chosen,
                                std::vector<std::vector<double>>{first.se, seconds[*b2].se}, *last);
        for (std::size_t i = 0; i < refits.size(); ++i) {
          out.named_effects[i] = estimate_of(refits[i]);
          last = &refits[i];
        }
      }
    }
  }
  report(1.0);
  // Named second after a first that passed where it did not: named all the same.
  if (named_in(out.named_effects, out.most_likely_candidate)) out.not_named_reason.clear();
  const std::vector<double>& heldout = last->heldout.force;
  out.extended_heldout_nrmse_pct = nrmse(last->heldout.force_sse(), pooled.norm);
  out.gap_shrink_pct = shrink(out.baseline_heldout_nrmse_pct, out.extended_heldout_nrmse_pct);
  out.zero_extended_heldout_nrmse_pct = nrmse(last->heldout.zero_sse(), pooled.zero_norm);
  out.zero_gap_shrink_pct =
      shrink(out.zero_baseline_heldout_nrmse_pct, out.zero_extended_heldout_nrmse_pct);

  std::vector<std::vector<double>> ext_preds;
  unit_costs(units, chosen, &ext_preds);
  out.map_after = residual_map(units, ext_preds, settings.phase_bins);
  out.regions = compare_regions(units, base, heldout);

  // Where: the cells whose residual exceeds the noise floor most; none under it, which would be
  // listed as what the model misses where it is only the noise.
  const auto excess = [](const ResidualCell& c) {
    return c.rms_n * c.rms_n - c.noise_floor_n * c.noise_floor_n;
  };
  std::vector<ResidualCell> cells;
  for (const ResidualCell& c : out.map_before.cells) {
    if (c.samples > 0 && excess(c) > 0.0) cells.push_back(c);
  }
  std::stable_sort(cells.begin(), cells.end(), [&](const ResidualCell& a, const ResidualCell& b) {
    return excess(a) > excess(b);
  });
  cells.resize(std::min(cells.size(), static_cast<std::size_t>(settings.top_cells)));
  out.where = cells;

  // By step: pooled over the step's regions.
  std::vector<double> sb(static_cast<std::size_t>(prep.steps), 0.0), se = sb, sn = sb;
  for (std::size_t ui = 0; ui < units.size(); ++ui) {
    const auto o = static_cast<std::size_t>(units[ui].ordinal);
    sb[o] += base[ui];
    se[o] += heldout[ui];
    sn[o] += units[ui].norm();
  }
  for (std::size_t o = 0; o < sb.size(); ++o) {
    out.per_step.push_back({prep.step_ids[o].first, prep.step_ids[o].second, nrmse(sb[o], sn[o]),
                            nrmse(se[o], sn[o])});
  }
  return out;
}

}  // namespace

DiscrepancyResult find_discrepancy(const DiscrepancyInput& input,
                                   const DiscrepancySettings& settings,
                                   const std::function<void(double)>& on_progress) {
  return discrepancy_without(input, settings, on_progress, {});
}

DiscrepancyResult find_discrepancy_undoing_creep(const DiscrepancyInput& input,
                                                 const ReadWithCreepUndone& read_with_creep_undone,
                                                 const DiscrepancySettings& settings,
                                                 const std::function<void(double)>& on_progress) {
  // Reading the session again takes a tenth of a run; the two runs take about as long.
  const auto share = [&](double from, double to) {
    return [&on_progress, from, to](double fraction) {
      if (on_progress) on_progress(from + (to - from) * fraction);
    };
  };
  DiscrepancyResult out = find_discrepancy(input, settings, share(0.0, 0.5));
  const auto creep = std::find_if(
      out.named_effects.begin(), out.named_effects.end(), [&](const EffectEstimate& e) {
        return effect_undone_in_readings(e, out.zero_gap_shrink_pct, settings.min_zero_shrink_pct);
      });
  if (creep == out.named_effects.end()) {
    share(0.0, 1.0)(1.0);
    return out;
  }
  const DiscrepancyInput undone_input = read_with_creep_undone(creep_correction(*creep));
  share(0.0, 1.0)(0.55);
  // One effect on top of the creep, as a second effect on top of a first.
  DiscrepancySettings on_top = settings;
  on_top.second_effect = false;
  const DiscrepancyResult undone =
      discrepancy_without(undone_input, on_top, share(0.55, 1.0), "sensor_creep");

  CreepUndoneInReadings& u = out.creep_undone.emplace();
  u.creep = *creep;
  u.steps = undone.steps;
  u.baseline_heldout_nrmse_pct = undone.baseline_heldout_nrmse_pct;
  u.most_likely_candidate = undone.most_likely_candidate;
  u.not_named_reason = undone.not_named_reason;

  out.named_effects = {u.creep};
  out.named_effects.insert(out.named_effects.end(), undone.named_effects.begin(),
                           undone.named_effects.end());
  out.extended_heldout_nrmse_pct = undone.extended_heldout_nrmse_pct;
  out.gap_shrink_pct = shrink(out.baseline_heldout_nrmse_pct, out.extended_heldout_nrmse_pct);
  out.map_after = undone.map_after;
  for (std::size_t i = 0; i < out.regions.size() && i < undone.regions.size(); ++i) {
    out.regions[i].extended_heldout_nrmse_pct = undone.regions[i].extended_heldout_nrmse_pct;
  }
  for (StepComparison& s : out.per_step) {
    const auto it =
        std::find_if(undone.per_step.begin(), undone.per_step.end(),
                     [&](const StepComparison& o) { return o.foot == s.foot && o.step == s.step; });
    s.extended_nrmse_pct = it != undone.per_step.end() ? it->extended_nrmse_pct
                                                       : std::numeric_limits<double>::quiet_NaN();
  }
  out.second_candidates = undone.candidates;
  if (named_in(out.named_effects, out.most_likely_candidate)) {
    out.not_named_reason.clear();
  } else {
    const auto there =
        std::find_if(undone.candidates.begin(), undone.candidates.end(),
                     [&](const CandidateResult& c) { return c.name == out.most_likely_candidate; });
    const std::string why =
        undone.most_likely_candidate == out.most_likely_candidate ? undone.not_named_reason
        : there != undone.candidates.end()
            ? fmt::format("its held-out gain there is {:.1f} % (the most likely there is {})",
                          there->shrink_pct, undone.most_likely_candidate)
            : std::string("it is not a candidate there");
    out.not_named_reason =
        fmt::format("with the sensor creep that the zeros show undone in the readings, {}", why);
  }
  return out;
}

ExtendedModelFit fit_extended_model(const DiscrepancyInput& input,
                                    std::span<const std::string> effects,
                                    const DiscrepancySettings& settings,
                                    const std::stop_token& stop,
                                    const std::function<void(double)>& on_progress) {
  check_settings(settings, input);
  for (std::size_t i = 0; i < effects.size(); ++i) {
    check_discrepancy_effect(effects[i]);
    for (std::size_t j = 0; j < i; ++j) {
      if (effects[i] == effects[j]) {
        throw std::invalid_argument("effect '" + effects[i] + "' given twice");
      }
    }
  }
  check_crosstalk_views(input, effects);
  const Prepared prep = prepare(input, settings.folds);
  // Fitted on no unit, the coupling would be a minimum of nothing.
  if (names_crosstalk(effects) &&
      std::none_of(prep.units.begin(), prep.units.end(),
                   [](const Unit& u) { return u.crosstalk != nullptr; })) {
    throw std::invalid_argument(
        "crosstalk: no region-step has readings corrected for it (the steps were measured again "
        "from another contact area source than the analyses')");
  }
  const auto specs = candidate_specs(input.cell_area_mm2, input.newtons_per_bit);
  ExtendedModelFit out;
  const Costs base = unit_costs(prep.units, {});
  out.baseline_nrmse_pct = nrmse(base.force_sse(), prep.pooled.norm);
  out.baseline_heldout_nrmse_pct = out.baseline_nrmse_pct;
  out.zero_changes = prep.pooled.zero_channel ? prep.pooled.zero_changes : 0;
  out.zero_baseline_heldout_nrmse_pct = nrmse(base.zero_sse(), prep.pooled.zero_norm);
  std::vector<FixedEffect> chosen;
  Costs heldout = base;
  Costs in_sample = base;
  std::optional<CandidateOutcome> last_fit;
  std::vector<std::vector<double>> had_se;
  for (const std::string& name : effects) {
    const CandidateOutcome c =
        fit_candidate(prep.units, prep.pooled, chosen, spec_named(specs, name), stop);
    out.effects.push_back(estimate_of(c));
    chosen.push_back({c.spec, c.theta});
    had_se.push_back(c.se);
    heldout = c.heldout;
    in_sample = c.in_sample;
    last_fit = c;
    if (on_progress) {
      // With two or more, each is fitted once more (refit_together).
      on_progress(static_cast<double>(chosen.size()) /
                  static_cast<double>(effects.size() < 2 ? 1 : 2 * effects.size()));
    }
  }
  if (chosen.size() >= 2) {
    const std::vector<CandidateOutcome> refits =
        refit_together(prep.units, prep.pooled, chosen, had_se, *last_fit, stop);
    for (std::size_t i = 0; i < refits.size(); ++i) out.effects[i] = estimate_of(refits[i]);
    if (!refits.empty()) {
      heldout = refits.back().heldout;
      in_sample = refits.back().in_sample;
    }
    if (on_progress) on_progress(1.0);
  }
  out.extended_nrmse_pct = nrmse(in_sample.force_sse(), prep.pooled.norm);
  out.extended_heldout_nrmse_pct = nrmse(heldout.force_sse(), prep.pooled.norm);
  out.zero_extended_heldout_nrmse_pct = nrmse(heldout.zero_sse(), prep.pooled.zero_norm);
  out.regions = compare_regions(prep.units, base.force, heldout.force);
  return out;
}

bool effect_inside_tissue_fit(std::string_view name) {
  check_discrepancy_effect(name);
  const auto specs = candidate_specs(1.0, 1.0);
  const CandidateSpec& spec = spec_named(specs, name);
  return spec.stage == 0;
}

bool crosstalk_left_out(const CellReadingEvidence& cells, std::span<const std::string> effects) {
  return cells.shows_crosstalk() && !names_crosstalk(effects);
}

bool effect_undone_in_readings(const EffectEstimate& effect, double zero_shrink_pct,
                               double min_zero_shrink_pct) {
  check_discrepancy_effect(effect.name);
  return effect.name == "sensor_creep" && zero_shrink_pct >= min_zero_shrink_pct &&
         std::all_of(effect.params.begin(), effect.params.end(),
                     [](const ParamEstimate& p) { return std::isfinite(p.se) && p.se > 0.0; });
}

bool effect_undone_in_readings(const ExtendedModelFit& fit, const EffectEstimate& effect,
                               double min_zero_shrink_pct) {
  const double zero_shrink_pct = fit.zero_baseline_heldout_nrmse_pct > 0.0
                                     ? 100.0 * (1.0 - fit.zero_extended_heldout_nrmse_pct /
                                                          fit.zero_baseline_heldout_nrmse_pct)
                                     : 0.0;
  return effect_undone_in_readings(effect, zero_shrink_pct, min_zero_shrink_pct);
}

std::optional<CreepCorrection> creep_to_undo(const ExtendedModelFit& fit,
                                             double min_zero_shrink_pct) {
  for (const EffectEstimate& e : fit.effects) {
    if (effect_undone_in_readings(fit, e, min_zero_shrink_pct)) return creep_correction(e);
  }
  return std::nullopt;
}

CreepCorrection creep_correction(const EffectEstimate& sensor_creep) {
  const auto param = [&](std::string_view name) {
    const auto it = std::find_if(sensor_creep.params.begin(), sensor_creep.params.end(),
                                 [&](const ParamEstimate& p) { return p.name == name; });
    if (it == sensor_creep.params.end()) {
      throw std::invalid_argument(fmt::format("{} without its {}", sensor_creep.name, name));
    }
    return it->value;
  };
  return CreepCorrection(param("gain"), param("tau_s"));
}

ExtendedModelFit with_creep_undone(const ExtendedModelFit& as_read,
                                   const ExtendedModelFit& undone) {
  std::vector<std::string> others, fitted;
  bool creep = false;
  for (const EffectEstimate& e : as_read.effects) {
    if (e.name == "sensor_creep") {
      creep = true;
    } else {
      others.push_back(e.name);
    }
  }
  for (const EffectEstimate& e : undone.effects) fitted.push_back(e.name);
  if (!creep || others != fitted) {
    throw std::invalid_argument(fmt::format(
        "with_creep_undone: the effects as read ({}) are not sensor_creep and those with it undone "
        "({})",
        fmt::join(others, ", "), fmt::join(fitted, ", ")));
  }
  ExtendedModelFit out = as_read;
  auto next = undone.effects.begin();
  for (EffectEstimate& e : out.effects) {
    if (e.name != "sensor_creep") e = *next++;
  }
  out.extended_nrmse_pct = undone.extended_nrmse_pct;
  out.extended_heldout_nrmse_pct = undone.extended_heldout_nrmse_pct;
  for (std::size_t i = 0; i < out.regions.size() && i < undone.regions.size(); ++i) {
    out.regions[i].extended_heldout_nrmse_pct = undone.regions[i].extended_heldout_nrmse_pct;
  }
  return out;
}

namespace {

// fit_steps_with_effects for the steps of `input` that `wanted` (by their index in input.steps)
// takes, into out[that index]; the others only carry into them what they carry.
void refit_with_effects(const DiscrepancyInput& input, std::span<const EffectEstimate> effects,
                        const Config& config, const AnalysisSettings& settings,
                        const std::function<bool(std::size_t)>& wanted,
                        std::vector<StepAnalysis>& out) {
  const auto specs = candidate_specs(input.cell_area_mm2, input.newtons_per_bit);
  std::vector<FixedEffect> inside;
  for (const EffectEstimate& e : effects) {
    check_discrepancy_effect(e.name);
    const CandidateSpec& spec = spec_named(specs, e.name);
    if (spec.stage != 0) continue;
    std::vector<double> theta;
    for (const ParamSpec& p : spec.params) {
      const auto it = std::find_if(e.params.begin(), e.params.end(),
                                   [&](const ParamEstimate& q) { return q.name == p.name; });
      if (it == e.params.end()) {
        throw std::invalid_argument(e.name + ": no estimate of its parameter '" + p.name + "'");
      }
      theta.push_back(it->value);
    }
    inside.push_back({&spec, std::move(theta)});
  }
  if (inside.empty()) return;
  if (settings.fit.mode != FitMode::Identifiable || settings.fit.free_scale) {
    throw std::invalid_argument(
        "effects inside the tissue fit need the default fit (identifiable parameters, P "
        "declared), not --fit seed8 or --free-scale");
  }
  // Shared by every region-step's transform, which the session-level fit runs again later.
  struct Effects {
    Prepared prep;
    Model model;
    Chain chain;
  };
  auto fx = std::make_shared<Effects>();
  fx->prep = prepare(input, 2);
  fx->model = build(fx->prep.units, inside);
  fx->chain = fx->model.chain();
  const std::shared_ptr<const Effects> shared = fx;
  std::map<std::pair<Foot, int>, std::size_t> step_of;
  for (std::size_t i = 0; i < input.steps.size(); ++i) {
    const StepAnalysis& a = input.steps[i].analysis;
    step_of[{a.foot, a.step}] = i;
  }
  const Chain& chain = shared->chain;
  std::vector<std::size_t> refit;
  for (std::size_t ui = 0; ui < shared->prep.units.size(); ++ui) {
    const Unit& u = shared->prep.units[ui];
    if (wanted(step_of.at({u.foot, u.step})) &&
        std::any_of(chain.begin(), chain.end(), [&](const Applied* e) { return e->affects(u); })) {
      refit.push_back(ui);
    }
  }
  parallel_for(refit.size(), [&](std::size_t ri) {
    const std::size_t ui = refit[ri];
    const Unit& u = shared->prep.units[ui];
    std::size_t choices = 1;
    for (const Applied* e : chain) {
      if (e->affects(u)) choices = std::max(choices, e->choices(u));
    }
    RegionAnalysis& ra = out[step_of.at({u.foot, u.step})].regions[index_of(u.region)];
    const std::size_t n = u.y.size();
    const std::vector<double> zeros(n, 0.0);
    Workspace w;
    std::optional<RegionFit> best;
    std::shared_ptr<const ForceTransform> best_transform;
    for (std::size_t c = 0; c < choices; ++c) {
      auto transform = std::make_shared<ForceTransform>();
      std::vector<double> y(n), at_zero(n);
      transform->offset_n.assign(ra.series.t_s.size(), 0.0);
      run_chain(chain, ui, u, u, zeros, y, w, c);
      for (std::size_t k = 0; k < n; ++k) transform->offset_n[u.series_frames[k]] = y[k];
      // The linear part is the chain without what it adds, less that chain's response to no
      // force (relaxation's carried-in lag). Each transform has its own scratch.
      run_chain(chain, ui, u, u, zeros, at_zero, w, c, true);
      transform->linear = [shared, ui, c, at_zero, x = std::vector<double>(n),
                           y = std::vector<double>(n), w = Workspace{}](
                              std::span<const double> tissue, std::span<double> reported) mutable {
        const Unit& unit = shared->prep.units[ui];
        for (std::size_t k = 0; k < x.size(); ++k) x[k] = tissue[unit.series_frames[k]];
        run_chain(shared->chain, ui, unit, unit, x, y, w, c, true);
        std::fill(reported.begin(), reported.end(), 0.0);
        for (std::size_t k = 0; k < x.size(); ++k) {
          reported[unit.series_frames[k]] = y[k] - at_zero[k];
        }
      };
      RegionFit fit =
          fit_region(ra.series, ra.declared, config.fit_bounds, settings.fit, transform.get());
      const bool better = !best || (fit.status == FitStatus::Ok && best->status != FitStatus::Ok) ||
                          (fit.status == best->status && fit.final_cost < best->final_cost);
      if (better) {
        best = std::move(fit);
        best_transform = std::move(transform);
      }
    }
    ra.fit = std::move(*best);
    ra.effects = std::move(best_transform);
  });
  std::vector<std::size_t> touched;
  for (std::size_t ui : refit) {
    const Unit& u = shared->prep.units[ui];
    touched.push_back(step_of.at({u.foot, u.step}));
  }
  std::sort(touched.begin(), touched.end());
  touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
  for (std::size_t i : touched) set_model_totals(out[i]);
}

}  // namespace

std::vector<StepAnalysis> fit_steps_with_effects(const DiscrepancyInput& input,
                                                 std::span<const EffectEstimate> effects,
                                                 const Config& config,
                                                 const AnalysisSettings& settings) {
  std::vector<StepAnalysis> out;
  for (const DiscrepancyStep& ds : input.steps) out.push_back(ds.analysis);
  refit_with_effects(
      input, effects, config, settings, [](std::size_t) { return true; }, out);
  return out;
}

StepAnalysis fit_step_with_effects(const DiscrepancyInput& input, std::size_t index,
                                   std::span<const EffectEstimate> effects, const Config& config,
                                   const AnalysisSettings& settings) {
  if (index >= input.steps.size()) {
    throw std::invalid_argument("fit_step_with_effects: step " + std::to_string(index) + " of " +
                                std::to_string(input.steps.size()));
  }
  // Only out[index] is read or written.
  std::vector<StepAnalysis> out(input.steps.size());
  out[index] = input.steps[index].analysis;
  refit_with_effects(
      input, effects, config, settings, [index](std::size_t i) { return i == index; }, out);
  return std::move(out[index]);
}

FixedEffectEvaluation evaluate_effect_at(const DiscrepancyInput& input, std::string_view effect,
                                         const std::map<std::string, double>& params,
                                         const DiscrepancySettings& settings) {
  check_settings(settings, input);
  check_discrepancy_effect(effect);
  check_crosstalk_views(input, std::vector<std::string>{std::string(effect)});
  const auto specs = candidate_specs(input.cell_area_mm2, input.newtons_per_bit);
  const CandidateSpec& spec = spec_named(specs, effect);
  for (const auto& given : params) {
    const std::string& name = given.first;
    const double value = given.second;
    const auto p = std::find_if(spec.params.begin(), spec.params.end(),
                                [&](const ParamSpec& q) { return q.name == name; });
    if (p == spec.params.end()) {
      throw std::invalid_argument(spec.name + " has no parameter '" + name + "'");
    }
    if (!(value >= p->lo && value <= p->hi)) {
      throw std::invalid_argument(spec.name + "." + name + " = " + std::to_string(value) +
                                  " is outside [" + std::to_string(p->lo) + ", " +
                                  std::to_string(p->hi) + "]");
    }
  }
  const std::vector<std::vector<double>> thetas = grid_of(spec, params);
  const Prepared prep = prepare(input, settings.folds);
  const Costs base = unit_costs(prep.units, {});
  std::vector<Costs> costs(thetas.size());
  parallel_for(thetas.size(), [&](std::size_t i) {
    const std::vector<FixedEffect> fx{{&spec, thetas[i]}};
    costs[i] = unit_costs(prep.units, fx);
  });
  std::size_t best = 0;
  for (std::size_t i = 1; i < costs.size(); ++i) {
    if (deviance(costs[i].force_sse(), costs[i].zero_sse(), prep.pooled) <
        deviance(costs[best].force_sse(), costs[best].zero_sse(), prep.pooled)) {
      best = i;
    }
  }
  FixedEffectEvaluation out;
  for (std::size_t p = 0; p < spec.params.size(); ++p) {
    out.params.push_back({spec.params[p].name, thetas[best][p], 0.0});
  }
  out.baseline_nrmse_pct = nrmse(base.force_sse(), prep.pooled.norm);
  out.extended_nrmse_pct = nrmse(costs[best].force_sse(), prep.pooled.norm);
  out.zero_baseline_nrmse_pct = nrmse(base.zero_sse(), prep.pooled.zero_norm);
  out.zero_extended_nrmse_pct = nrmse(costs[best].zero_sse(), prep.pooled.zero_norm);
  return out;
}

}  // namespace gaitmon
