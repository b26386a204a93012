// Per-region fits of the ellipsoid tissue model. The default (P, C, d0 declared) is separable:
// an exact inner solve for K and D on a grid over the exponents (n, m), then a bounded
// Levenberg-Marquardt with analytic derivatives. Free P and seed8 use Ceres with automatic
// derivatives and a log-linear initial guess plus deterministic extra starts. Both give standard
// errors from the Jacobian at the optimum and a rank check that names what the data cannot see.
//
// Non-negative force: like the seed's eq 57, a penalty, here as one extra residual per frame,
// kPenaltyWeight x max(0, -F_model), so a model that pulls on the foot costs far more than a
// misfit of the same size. The reported model force is the raw model (never clipped), so a
// caller sees any residual negativity.
#include "gaitmon/tissue_fit.hpp"

#include <ceres/ceres.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <boost/math/tools/minima.hpp>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <utility>

namespace gaitmon {

std::string_view smoothing_name(Smoothing smoothing) {
  return smoothing == Smoothing::Seed ? "seed" : "none";
}

std::optional<Smoothing> parse_smoothing(std::string_view text) {
  if (text == "none") return Smoothing::None;
  if (text == "seed") return Smoothing::Seed;
  return std::nullopt;
}

std::string_view end_rate_name(EndRate rate) {
  return rate == EndRate::SecondOrder ? "second-order" : "two-frame";
}

std::optional<EndRate> parse_end_rate(std::string_view text) {
  if (text == "two-frame") return EndRate::TwoFrame;
  if (text == "second-order") return EndRate::SecondOrder;
  return std::nullopt;
}

std::string_view fit_mode_name(FitMode mode) {
  return mode == FitMode::Seed8 ? "seed8" : "identifiable";
}

std::optional<FitMode> parse_fit_mode(std::string_view text) {
  if (text == "identifiable") return FitMode::Identifiable;
  if (text == "seed8") return FitMode::Seed8;
  return std::nullopt;
}

std::string_view fit_status_name(FitStatus status) {
  switch (status) {
    case FitStatus::Ok:
      return "ok";
    case FitStatus::NoContact:
      return "no_contact";
    case FitStatus::Failed:
      break;
  }
  return "fit_failed";
}

std::vector<FrameRun> contact_runs(std::span<const double> area_mm2) {
  std::vector<FrameRun> runs;
  std::size_t begin = 0;
  while (begin < area_mm2.size()) {
    if (!(area_mm2[begin] > 0.0)) {
      ++begin;
      continue;
    }
    std::size_t end = begin;
    while (end < area_mm2.size() && area_mm2[end] > 0.0) ++end;
    runs.push_back({begin, end});
    begin = end;
  }
  return runs;
}

double nrmse_pct(std::span<const double> measured, std::span<const double> model) {
  if (measured.size() != model.size()) {
    throw std::invalid_argument("nrmse_pct: measured and model differ in length");
  }
  if (measured.empty()) return 0.0;
  double sum = 0.0;
  double peak = 0.0;
  for (std::size_t i = 0; i < measured.size(); ++i) {
    sum += (measured[i] - model[i]) * (measured[i] - model[i]);
    peak = std::max(peak, measured[i]);
  }
  if (peak <= 0.0) return 0.0;
  return std::sqrt(sum / static_cast<double>(measured.size())) / peak * 100.0;
}

namespace {

constexpr double kPenaltyWeight = 1e3;
// Keeps g real when a free P is driven below the measured area: the contact plane at the equator.
constexpr double kMaxAreaFraction = 0.999;
constexpr double kBoundTolerance = 1e-6;
// A normalised Jacobian column whose part independent of the columns before it is smaller than
// this is a combination of them: the data cannot separate that parameter.
constexpr double kDependentColumn = 1e-6;

// The eight physical parameters in a fixed order, the order of RegionFit's estimates.
enum Phys { kA, kB, kC, kD0, kKbar, kN, kCbar, kM, kPhysCount };
constexpr std::array<const char*, kPhysCount> kPhysNames{
    "A_mm", "B_mm", "C_mm", "d0_mm", "kbar_n_per_mm3", "n", "cbar_ns_per_mm3", "m"};

// One fitted frame. gdot is either a difference of g at two neighbouring areas (raw series) or
// the chain rule on an area rate (smoothed, or second-order at a run's ends); both are evaluated
// with the current P.
struct FitFrame {
  double area_mm2 = 0.0;
  double force_n = 0.0;  ///< the target (smoothed under Smoothing::Seed)
  double area_lo_mm2 = 0.0;
  double area_hi_mm2 = 0.0;
  double dt_s = 0.0;  ///< 0: gdot from area_rate
  double area_rate_mm2_per_s = 0.0;
  std::size_t input_index = 0;  ///< where the model force goes in RegionFit::model_force_n
};

// The effects between the tissue and the cells (ForceTransform, one per stance or none) on
// per-fit-frame vectors: each stance's linear part runs on its input frames, with 0 in the frames
// not fitted. Holds scratch, so one per fit.
class ReportedForce {
 public:
  ReportedForce(const std::vector<FitFrame>& frames, std::span<const std::size_t> stance_begin,
                std::span<const ForceTransform* const> transforms, std::size_t input_size)
      : frames_(&frames),
        begin_(stance_begin.begin(), stance_begin.end()),
        transforms_(transforms.begin(), transforms.end()),
        offset_(frames.size(), 0.0) {
    begin_.push_back(input_size);
    identity_ = std::all_of(transforms_.begin(), transforms_.end(),
                            [](const ForceTransform* t) { return t == nullptr; });
    if (identity_) return;
    input_.assign(input_size, 0.0);
    output_.assign(input_size, 0.0);
    std::vector<double> per_input(input_size, 0.0);
    for (std::size_t s = 0; s < transforms_.size(); ++s) {
      const ForceTransform* t = transforms_[s];
      if (t == nullptr) continue;
      if (!t->linear || t->offset_n.size() != begin_[s + 1] - begin_[s]) {
        throw std::invalid_argument(
            "ForceTransform: a linear map and one offset per frame of its series are needed");
      }
      std::copy(t->offset_n.begin(), t->offset_n.end(),
                per_input.begin() + static_cast<std::ptrdiff_t>(begin_[s]));
    }
    for (std::size_t i = 0; i < frames.size(); ++i) offset_[i] = per_input[frames[i].input_index];
  }
  bool identity() const { return identity_; }
  const std::vector<double>& offset() const { return offset_; }
  // The linear part, in place on a vector over the fit's frames.
  void linear(double* per_frame) const {
    if (identity_) return;
    std::fill(input_.begin(), input_.end(), 0.0);
    for (std::size_t i = 0; i < frames_->size(); ++i) {
      input_[(*frames_)[i].input_index] = per_frame[i];
    }
    output_ = input_;
    for (std::size_t s = 0; s < transforms_.size(); ++s) {
      if (transforms_[s] == nullptr) continue;
      const std::size_t b = begin_[s], n = begin_[s + 1] - b;
      transforms_[s]->linear(std::span<const double>(input_.data() + b, n),
                             std::span<double>(output_.data() + b, n));
    }
    for (std::size_t i = 0; i < frames_->size(); ++i) {
      per_frame[i] = output_[(*frames_)[i].input_index];
    }
  }

 private:
  const std::vector<FitFrame>* frames_;
  std::vector<std::size_t> begin_;
  std::vector<const ForceTransform*> transforms_;
  bool identity_ = true;
  std::vector<double> offset_;
  mutable std::vector<double> input_, output_;
};

// How the free vector theta maps to the physical parameters.
struct Layout {
  // Index into theta per physical parameter, or -1 if declared. Log-scaled unless n or m.
  std::array<int, kPhysCount> index{-1, -1, -1, -1, -1, -1, -1, -1};
  int log_p = -1;  ///< free_scale: log P in theta, A/B kept
  std::array<double, kPhysCount> declared{};
  std::vector<double> lower, upper;  ///< theta bounds
  std::vector<int> phys;             ///< theta index -> physical parameter, -1 for log P
  std::vector<std::string> names;    ///< theta names (physical, for `undetermined`)
  int size() const { return static_cast<int>(lower.size()); }
};

bool is_log(int phys) {
  return phys != kN && phys != kM;
}

template <class T>
T area_g(const T& area, const T& P) {
  using std::sqrt;
  T a = area / P;
  if (a > T(kMaxAreaFraction)) a = T(kMaxAreaFraction);
  return T(1.0) - sqrt(T(1.0) - a);
}

struct ForceModel {
  const std::vector<FitFrame>* frames;
  const Layout* layout;
  ModelVariant variant;

  template <class T>
  T phys(const T* theta, int p) const {
    using std::exp;
    const int i = layout->index[static_cast<std::size_t>(p)];
    if (i < 0) return T(layout->declared[static_cast<std::size_t>(p)]);
    return is_log(p) ? exp(theta[i]) : theta[i];
  }

  template <class T>
  void forces(const T* theta, T* out) const {
    using std::exp;
    using std::log;
    T P;
    if (layout->log_p >= 0) {
      P = exp(theta[layout->log_p]);
    } else {
      P = T(std::numbers::pi) * phys(theta, kA) * phys(theta, kB);
    }
    const T logC = log(phys(theta, kC));
    const T logd0 = log(phys(theta, kD0));
    const T n = phys(theta, kN);
    const T m = phys(theta, kM);
    const T K = phys(theta, kKbar) * exp((T(1.0) + n) * logC - n * logd0);
    const T D = phys(theta, kCbar) * exp((T(1.0) + m) * logC - m * logd0);
    for (std::size_t i = 0; i < frames->size(); ++i) {
      const FitFrame& f = (*frames)[i];
      const T g = area_g(T(f.area_mm2), P);
      T gdot;
      if (f.dt_s > 0.0) {
        gdot = (area_g(T(f.area_hi_mm2), P) - area_g(T(f.area_lo_mm2), P)) / T(f.dt_s);
      } else {
        using std::sqrt;
        T a = T(f.area_mm2) / P;
        if (a > T(kMaxAreaFraction)) a = T(kMaxAreaFraction);
        gdot = T(f.area_rate_mm2_per_s) / (P * T(2.0) * sqrt(T(1.0) - a));
      }
      out[i] = ellipsoid_force(P, K, n, D, m, g, gdot, variant);
    }
  }
};

struct DataResidual {
  ForceModel model;
  template <class T>
  bool operator()(T const* const* params, T* residuals) const {
    model.forces(params[0], residuals);
    for (std::size_t i = 0; i < model.frames->size(); ++i) {
      residuals[i] = residuals[i] - T((*model.frames)[i].force_n);
    }
    return true;
  }
};

struct PenaltyResidual {
  ForceModel model;
  template <class T>
  bool operator()(T const* const* params, T* residuals) const {
    model.forces(params[0], residuals);
    for (std::size_t i = 0; i < model.frames->size(); ++i) {
      residuals[i] = residuals[i] < T(0.0) ? T(-kPenaltyWeight) * residuals[i] : T(0.0);
    }
    return true;
  }
};

using Series = std::vector<std::pair<double, double>>;  // (t, value) of one contact run

// Least-squares polynomial of degree <= 5 in normalised time; returns values and derivatives
// (per second) at the run's own times.
void polynomial_fit(const std::vector<double>& t, const std::vector<double>& y,
                    std::vector<double>& value, std::vector<double>& rate) {
  const std::size_t n = t.size();
  value = y;
  rate.assign(n, 0.0);
  if (n < 2) return;
  const int degree = static_cast<int>(std::min<std::size_t>(5, n - 1));
  const double t0 = t.front();
  const double span = t.back() - t.front();
  if (span <= 0.0) return;
  Eigen::MatrixXd V(static_cast<Eigen::Index>(n), degree + 1);
  Eigen::VectorXd Y(static_cast<Eigen::Index>(n));
  for (std::size_t i = 0; i < n; ++i) {
    const double x = 2.0 * (t[i] - t0) / span - 1.0;
    double power = 1.0;
    for (int j = 0; j <= degree; ++j) {
      V(static_cast<Eigen::Index>(i), j) = power;
      power *= x;
    }
    Y(static_cast<Eigen::Index>(i)) = y[i];
  }
  const Eigen::VectorXd c = V.colPivHouseholderQr().solve(Y);
  for (std::size_t i = 0; i < n; ++i) {
    const double x = 2.0 * (t[i] - t0) / span - 1.0;
    double v = 0.0;
    double dv = 0.0;
    double power = 1.0;
    for (int j = 0; j <= degree; ++j) {
      v += c(j) * power;
      if (j + 1 <= degree) dv += static_cast<double>(j + 1) * c(j + 1) * power;
      power *= x;
    }
    value[i] = v;
    rate[i] = dv * 2.0 / span;
  }
}

// Appends the contact frames of one stance. Runs of contact are treated separately so that
// gdot never bridges a gap without contact.
void append_frames(const RegionSeries& s, Smoothing smoothing, EndRate end_rate, std::size_t offset,
                   std::vector<FitFrame>& frames) {
  for (const auto [begin, end] : contact_runs(s.area_mm2)) {
    const std::size_t len = end - begin;
    if (smoothing == Smoothing::None) {
      for (std::size_t i = begin; i < end; ++i) {
        FitFrame f;
        f.area_mm2 = s.area_mm2[i];
        f.force_n = s.force_n[i];
        const std::size_t lo = i > begin ? i - 1 : i;
        const std::size_t hi = i + 1 < end ? i + 1 : i;
        f.area_lo_mm2 = s.area_mm2[lo];
        f.area_hi_mm2 = s.area_mm2[hi];
        f.dt_s = hi > lo ? s.t_s[hi] - s.t_s[lo] : 0.0;
        if (end_rate == EndRate::SecondOrder && len >= 3 && (i == begin || i + 1 == end)) {
          // One-sided over three frames, pointing into the run: h < 0 at its last frame.
          const std::size_t i1 = i == begin ? i + 1 : i - 1;
          const std::size_t i2 = i == begin ? i + 2 : i - 2;
          const double h = s.t_s[i1] - s.t_s[i];
          f.area_rate_mm2_per_s =
              (-3.0 * s.area_mm2[i] + 4.0 * s.area_mm2[i1] - s.area_mm2[i2]) / (2.0 * h);
          f.dt_s = 0.0;
        }
        f.input_index = offset + i;
        frames.push_back(f);
      }
    } else {
      std::vector<double> t(s.t_s.begin() + static_cast<std::ptrdiff_t>(begin),
                            s.t_s.begin() + static_cast<std::ptrdiff_t>(end));
      std::vector<double> area(len);
      for (std::size_t i = 0; i < len; ++i) {
        const std::size_t lo = i > 0 ? i - 1 : i;
        const std::size_t hi = i + 1 < len ? i + 1 : i;
        double sum = 0.0;
        for (std::size_t j = lo; j <= hi; ++j) sum += s.area_mm2[begin + j];
        area[i] = sum / static_cast<double>(hi - lo + 1);
      }
      std::vector<double> force(s.force_n.begin() + static_cast<std::ptrdiff_t>(begin),
                                s.force_n.begin() + static_cast<std::ptrdiff_t>(end));
      std::vector<double> area_fit, area_rate, force_fit, force_rate;
      polynomial_fit(t, area, area_fit, area_rate);
      polynomial_fit(t, force, force_fit, force_rate);
      const double floor = 1e-3 * *std::max_element(area.begin(), area.end());
      for (std::size_t i = 0; i < len; ++i) {
        FitFrame f;
        f.area_mm2 = std::max(area_fit[i], floor);
        f.force_n = force_fit[i];
        f.area_rate_mm2_per_s = area_rate[i];
        f.input_index = offset + begin + i;
        frames.push_back(f);
      }
    }
  }
}

void check_bounds(const Bounds& b, const char* name) {
  if (!(b.lower > 0.0) || !(b.upper > b.lower) || !std::isfinite(b.upper)) {
    throw std::invalid_argument(std::string("fit bounds for ") + name +
                                " must satisfy 0 < lower < upper");
  }
}

std::array<Bounds, kPhysCount> phys_bounds(const FitBounds& b) {
  return {b.A_mm, b.B_mm, b.C_mm, b.d0_mm, b.kbar_n_per_mm3, b.n, b.cbar_ns_per_mm3, b.m};
}

std::array<double, kPhysCount> phys_values(const EllipsoidParams& p) {
  return {p.A_mm, p.B_mm, p.C_mm, p.d0_mm, p.kbar_n_per_mm3, p.n, p.cbar_ns_per_mm3, p.m};
}

double to_theta(int p, double value) {
  return is_log(p) ? std::log(value) : value;
}

Layout make_layout(const EllipsoidParams& declared, const FitBounds& bounds,
                   const FitSettings& settings) {
  Layout layout;
  layout.declared = phys_values(declared);
  const auto pb = phys_bounds(bounds);
  const auto add = [&](int p) {
    layout.index[static_cast<std::size_t>(p)] = layout.size();
    const Bounds& b = pb[static_cast<std::size_t>(p)];
    layout.lower.push_back(to_theta(p, b.lower));
    layout.upper.push_back(to_theta(p, b.upper));
    layout.names.emplace_back(kPhysNames[static_cast<std::size_t>(p)]);
    layout.phys.push_back(p);
  };
  // The material parameters come first: the rank check names the later of two parameters that
  // trade off, and the geometry is what the data cannot see (model-notes section 2).
  for (int p : {kKbar, kN, kCbar, kM}) add(p);
  if (settings.declared_m) {
    // Kept in theta, so the separable fit's four-vector stays, with its bounds closed on it.
    const auto m = static_cast<std::size_t>(layout.index[kM]);
    layout.lower[m] = layout.upper[m] = *settings.declared_m;
  }
  if (settings.mode == FitMode::Seed8) {
    for (int p : {kA, kB, kC, kD0}) add(p);
    return layout;
  }
  if (settings.free_scale) {
    layout.log_p = layout.size();
    layout.lower.push_back(std::log(std::numbers::pi * bounds.A_mm.lower * bounds.B_mm.lower));
    layout.upper.push_back(std::log(std::numbers::pi * bounds.A_mm.upper * bounds.B_mm.upper));
    layout.names.emplace_back("P_mm2");
    layout.phys.push_back(-1);
  }
  return layout;
}

double clamp_into(double v, double lo, double hi) {
  const double margin = 1e-9 * (hi - lo);
  return std::clamp(v, lo + margin, hi - margin);
}

// Starts for the Identifiable mode: log-linear least squares of the elastic part with n free,
// then with n fixed at the bounds' quartiles; damping small, m mid-range.
std::vector<std::vector<double>> initial_guesses(const std::vector<FitFrame>& frames,
                                                 const Layout& layout,
                                                 const FitSettings& settings) {
  const int np = layout.size();
  const auto mid = [&](int i) { return 0.5 * (layout.lower[i] + layout.upper[i]); };
  std::vector<std::vector<double>> starts;
  if (settings.mode == FitMode::Seed8) {
    std::vector<double> s(static_cast<std::size_t>(np));
    for (int i = 0; i < np; ++i) {
      const int p = layout.phys[static_cast<std::size_t>(i)];
      const double lo = is_log(p) ? std::exp(layout.lower[i]) : layout.lower[i];
      const double hi = is_log(p) ? std::exp(layout.upper[i]) : layout.upper[i];
      s[static_cast<std::size_t>(i)] = to_theta(p, 0.5 * (lo + hi));
    }
    starts.push_back(s);
    return starts;
  }
  const auto& d = layout.declared;
  const double P = std::numbers::pi * d[kA] * d[kB];
  const double logC = std::log(d[kC]);
  const double logd0 = std::log(d[kD0]);
  double peak = 0.0;
  for (const FitFrame& f : frames) peak = std::max(peak, f.force_n);
  std::vector<double> x, y;
  for (const FitFrame& f : frames) {
    const double g = area_g(f.area_mm2, P);
    if (f.force_n > 0.02 * peak && g > 0.0) {
      x.push_back(std::log(g));
      y.push_back(std::log(f.force_n / (P * (1.0 - g / 3.0))));
    }
  }
  const int iN = layout.index[kN];
  const int iK = layout.index[kKbar];
  const int iC = layout.index[kCbar];
  const int iM = layout.index[kM];
  const double n_lo = layout.lower[iN];
  const double n_hi = layout.upper[iN];
  std::vector<double> n_values;
  if (x.size() >= 2) {
    double mx = 0.0, my = 0.0;
    for (std::size_t i = 0; i < x.size(); ++i) {
      mx += x[i];
      my += y[i];
    }
    mx /= static_cast<double>(x.size());
    my /= static_cast<double>(x.size());
    double sxy = 0.0, sxx = 0.0;
    for (std::size_t i = 0; i < x.size(); ++i) {
      sxy += (x[i] - mx) * (y[i] - my);
      sxx += (x[i] - mx) * (x[i] - mx);
    }
    if (sxx > 0.0) n_values.push_back(clamp_into(sxy / sxx - 2.0, n_lo, n_hi));
  }
  for (double q : {0.25, 0.75, 0.5}) n_values.push_back(n_lo + q * (n_hi - n_lo));
  for (double n : n_values) {
    if (static_cast<int>(starts.size()) >= std::max(1, settings.starts)) break;
    double logK = 0.0;
    for (std::size_t i = 0; i < x.size(); ++i) logK += y[i] - (2.0 + n) * x[i];
    if (!x.empty()) logK /= static_cast<double>(x.size());
    std::vector<double> s(static_cast<std::size_t>(np));
    s[static_cast<std::size_t>(iN)] = n;
    const double log_kbar = logK - (1.0 + n) * logC + n * logd0;
    s[static_cast<std::size_t>(iK)] =
        clamp_into(x.empty() ? mid(iK) : log_kbar, layout.lower[iK], layout.upper[iK]);
    s[static_cast<std::size_t>(iC)] =
        layout.lower[iC] + 0.1 * (layout.upper[iC] - layout.lower[iC]);
    s[static_cast<std::size_t>(iM)] = mid(iM);
    if (layout.log_p >= 0) {
      s[static_cast<std::size_t>(layout.log_p)] =
          clamp_into(std::log(P), layout.lower[layout.log_p], layout.upper[layout.log_p]);
    }
    starts.push_back(s);
  }
  return starts;
}

// What a solver hands back: the optimum in theta, the data residuals' Jacobian there (for the
// standard errors and the rank check) and the outcome.
struct Solution {
  std::vector<double> theta;
  Eigen::MatrixXd jacobian;
  std::string message;
  int iterations = 0;
  double cost = 0.0;  ///< 1/2 the sum of squared residuals, penalty included (Ceres' convention)
  bool converged = false;
  std::string failure;  ///< why not converged: no_convergence, solver_failure or non_finite
};

// ---- The default fit: separable in (K, D) given (n, m) ----
//
// With P, C and d0 declared, g and gdot are fixed by the data, and the model is linear in the
// combinations K and D for given exponents:
//   F_i = K e_i(n) + D v_i(m),  e_i = P g^(2+n) (1 - g/3),  v_i = s P g^(1+m) gdot h(g).
// For each (n, m) on a grid the best (K, D) inside their bounds, with the non-negativity penalty,
// is a small convex problem solved exactly; that profile is searched on the whole (n, m) box, so
// the global minimum is found without relying on starting points. The best grid point then
// starts a bounded Levenberg-Marquardt on (log kbar, n, log cbar, m) with analytic derivatives.
// Everything is a few passes over the frames: no allocation per iteration beyond the frame
// vectors, and no solver set-up.

constexpr int kGridN = 33;
constexpr int kGridM = 15;
// The shared m's search (fit_shared_damping_exponent): Brent's relative tolerance 2^(1 - bits) =
// 0.00024 ends it with m within about 0.001; it takes 5-11 evaluations, far under the cap.
constexpr int kBrentBits = 13;
constexpr std::uintmax_t kMaxBrentEvaluations = 50;
constexpr double kUnusableCost = 1e300;
constexpr int kMaxActiveSetRounds = 8;
constexpr double kFunctionTolerance = 1e-8;
constexpr double kParameterTolerance = 1e-8;
constexpr double kGradientTolerance = 1e-10;

struct SeparableData {
  std::vector<double> log_g;   ///< log g per frame
  std::vector<double> e_base;  ///< P g^2 (1 - g/3): e_i(n) = e_base exp(n log g)
  std::vector<double> v_base;  ///< s P g gdot h(g): v_i(m) = v_base exp(m log g)
  std::vector<double> force;
  double log_c = 0.0;      ///< log C
  double log_ratio = 0.0;  ///< log C - log d0: K = kbar exp(log_c + n log_ratio)
};

// `offset` (per frame) is what the effects report without a tissue force: the target is the
// force less it.
SeparableData separable_data(const std::vector<FitFrame>& frames, const Layout& layout,
                             ModelVariant variant, std::span<const double> offset) {
  const auto& d = layout.declared;
  const double P = std::numbers::pi * d[kA] * d[kB];
  SeparableData s;
  s.log_c = std::log(d[kC]);
  s.log_ratio = s.log_c - std::log(d[kD0]);
  for (const FitFrame& f : frames) {
    const double g = area_g(f.area_mm2, P);
    double gdot = 0.0;
    if (f.dt_s > 0.0) {
      gdot = (area_g(f.area_hi_mm2, P) - area_g(f.area_lo_mm2, P)) / f.dt_s;
    } else {
      const double a = std::min(f.area_mm2 / P, kMaxAreaFraction);
      gdot = f.area_rate_mm2_per_s / (P * 2.0 * std::sqrt(1.0 - a));
    }
    // ellipsoid_force at K = D = 1 and n = m = 0, split into its elastic and damping parts.
    const double elastic = ellipsoid_force(P, 1.0, 0.0, 0.0, 0.0, g, gdot, variant);
    const double total = ellipsoid_force(P, 1.0, 0.0, 1.0, 0.0, g, gdot, variant);
    s.log_g.push_back(g > 0.0 ? std::log(g) : -745.0);
    s.e_base.push_back(elastic);
    s.v_base.push_back(total - elastic);
    s.force.push_back(f.force_n - offset[s.force.size()]);
  }
  return s;
}

struct Coefficients {
  double K = 0.0;
  double D = 0.0;
  double cost = 0.0;  ///< sum of squared residuals, penalty included
};

// Sums over the frames for one (n, m): sum e^2, e F, v^2, v F, e v and F^2.
struct Moments {
  double ee = 0.0, eF = 0.0, vv = 0.0, vF = 0.0, ev = 0.0, FF = 0.0;
};

// The best (K, D) in [K_lo, K_hi] x [D_lo, D_hi] for fixed basis vectors e and v. The objective
// sum (K e + D v - F)^2 + w^2 sum_{K e + D v < 0} (K e + D v)^2 is convex: each round solves the
// box-constrained quadratic with the current negative set (interior solution, else the best of
// the four edges, where the 1-D minimiser is a clamp), until the negative set stops changing.
// With K, D > 0 and e >= 0 only frames with v < 0 (unloading) can go negative: `unloading` lists
// them, and `negative` is scratch of the same length.
Coefficients best_coefficients(const Moments& mo, std::span<const double> e,
                               std::span<const double> v, std::span<const std::size_t> unloading,
                               std::span<char> negative, double K_lo, double K_hi, double D_lo,
                               double D_hi) {
  const double w2 = kPenaltyWeight * kPenaltyWeight;
  double pee = 0.0, pev = 0.0, pvv = 0.0;  // the penalty's extra weight on negative frames
  std::fill(negative.begin(), negative.end(), 0);
  Coefficients best;
  for (int round = 0; round < kMaxActiveSetRounds; ++round) {
    double a = mo.ee + pee, b = mo.ev + pev, c = mo.vv + pvv;
    double K = 0.0, D = 0.0;
    const double det = a * c - b * b;
    bool interior = false;
    if (det > 1e-300 * a * c && a > 0.0) {
      K = (c * mo.eF - b * mo.vF) / det;
      D = (a * mo.vF - b * mo.eF) / det;
      interior = K >= K_lo && K <= K_hi && D >= D_lo && D <= D_hi;
    }
    const auto q = [&](double k, double d) {
      return a * k * k + 2.0 * b * k * d + c * d * d - 2.0 * (mo.eF * k + mo.vF * d);
    };
    if (!interior) {
      double best_q = std::numeric_limits<double>::infinity();
      const auto consider = [&](double k, double d) {
        const double value = q(k, d);
        if (value < best_q) {
          best_q = value;
          K = k;
          D = d;
        }
      };
      for (double k : {K_lo, K_hi}) {
        consider(k, c > 0.0 ? std::clamp((mo.vF - b * k) / c, D_lo, D_hi) : D_lo);
      }
      for (double d : {D_lo, D_hi}) {
        consider(a > 0.0 ? std::clamp((mo.eF - b * d) / a, K_lo, K_hi) : K_lo, d);
      }
    }
    bool changed = false;
    pee = pev = pvv = 0.0;
    for (std::size_t j = 0; j < unloading.size(); ++j) {
      const std::size_t i = unloading[j];
      const char neg = K * e[i] + D * v[i] < 0.0 ? 1 : 0;
      changed = changed || neg != negative[j];
      negative[j] = neg;
      if (neg) {
        pee += w2 * e[i] * e[i];
        pev += w2 * e[i] * v[i];
        pvv += w2 * v[i] * v[i];
      }
    }
    // The cost with the negative set the solution actually has.
    a = mo.ee + pee;
    b = mo.ev + pev;
    c = mo.vv + pvv;
    best = {K, D, mo.FF + q(K, D)};
    if (!changed) break;
  }
  return best;
}

// The data and penalty residuals and their Jacobian in theta = (log kbar, n, log cbar, m).
struct Residuals {
  Eigen::VectorXd r;  ///< data residuals, then penalty residuals
  Eigen::MatrixXd J;
};

// The penalty is on the tissue's force; the data rows compare what the cells report of it.
void evaluate(const SeparableData& s, const ReportedForce& reported, const Eigen::Vector4d& theta,
              Residuals& out) {
  const std::size_t n = s.force.size();
  const Eigen::Index N = static_cast<Eigen::Index>(n);
  out.r.resize(2 * N);
  out.J.resize(2 * N, 4);
  const double K = std::exp(theta(0) + s.log_c + theta(1) * s.log_ratio);
  const double D = std::exp(theta(2) + s.log_c + theta(3) * s.log_ratio);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Index row = static_cast<Eigen::Index>(i);
    const double elastic = K * s.e_base[i] * std::exp(theta(1) * s.log_g[i]);
    const double damping = D * s.v_base[i] * std::exp(theta(3) * s.log_g[i]);
    const double f = elastic + damping;
    const Eigen::RowVector4d grad(elastic, elastic * (s.log_ratio + s.log_g[i]), damping,
                                  damping * (s.log_ratio + s.log_g[i]));
    out.r(row) = f;
    out.J.row(row) = grad;
    if (f < 0.0) {
      out.r(N + row) = -kPenaltyWeight * f;
      out.J.row(N + row) = -kPenaltyWeight * grad;
    } else {
      out.r(N + row) = 0.0;
      out.J.row(N + row).setZero();
    }
  }
  // Column-major: each column's data rows are contiguous.
  reported.linear(out.r.data());
  for (Eigen::Index c = 0; c < 4; ++c) reported.linear(out.J.col(c).data());
  for (std::size_t i = 0; i < n; ++i) out.r(static_cast<Eigen::Index>(i)) -= s.force[i];
}

double grid_value(int i, int size, double lo, double hi) {
  return size == 1 ? lo : lo + (hi - lo) * static_cast<double>(i) / static_cast<double>(size - 1);
}

// The part of the separable fit that does not depend on m: the frames' data and the elastic
// bases over the grid of n with their moments. A profile over m (fit_shared_damping_exponent)
// prepares it once per stance and solves it at every m it tries.
struct SeparableProblem {
  SeparableData s;
  std::vector<double> e_grid;   ///< kGridN bases of all frames each
  std::vector<double> te_grid;  ///< what the cells report of them; empty where that is e_grid
  std::vector<double> ee, eF;
  double FF = 0.0;
  std::vector<std::size_t> unloading;  ///< frames where the damping basis is negative
};

SeparableProblem prepare_separable(const std::vector<FitFrame>& frames, const Layout& layout,
                                   ModelVariant variant, const ReportedForce& reported) {
  SeparableProblem p;
  p.s = separable_data(frames, layout, variant, reported.offset());
  const SeparableData& s = p.s;
  const auto in = static_cast<std::size_t>(layout.index[kN]);
  const std::size_t count = frames.size();
  p.e_grid.resize(kGridN * count);
  for (int a = 0; a < kGridN; ++a) {
    const double n = grid_value(a, kGridN, layout.lower[in], layout.upper[in]);
    for (std::size_t i = 0; i < count; ++i)
      p.e_grid[a * count + i] = s.e_base[i] * std::exp(n * s.log_g[i]);
  }
  if (!reported.identity()) {
    p.te_grid = p.e_grid;
    for (int a = 0; a < kGridN; ++a) reported.linear(&p.te_grid[a * count]);
  }
  const std::vector<double>& te_all = reported.identity() ? p.e_grid : p.te_grid;
  p.ee.assign(kGridN, 0.0);
  p.eF.assign(kGridN, 0.0);
  for (std::size_t i = 0; i < count; ++i) {
    p.FF += s.force[i] * s.force[i];
    if (s.v_base[i] < 0.0) p.unloading.push_back(i);
  }
  for (int a = 0; a < kGridN; ++a) {
    for (std::size_t i = 0; i < count; ++i) {
      const double e = te_all[a * count + i];
      p.ee[a] += e * e;
      p.eF[a] += e * s.force[i];
    }
  }
  return p;
}

Solution solve_separable(const SeparableProblem& p, const Layout& layout,
                         const FitSettings& settings, const ReportedForce& reported) {
  const SeparableData& s = p.s;
  const int iK = layout.index[kKbar], iN = layout.index[kN], iC = layout.index[kCbar],
            iM = layout.index[kM];
  const Eigen::Vector4d lower(layout.lower[iK], layout.lower[iN], layout.lower[iC],
                              layout.lower[iM]);
  const Eigen::Vector4d upper(layout.upper[iK], layout.upper[iN], layout.upper[iC],
                              layout.upper[iM]);
  const std::size_t count = s.force.size();

  // The profile over the (n, m) grid: the damping bases per grid value of m, once.
  const bool m_declared = settings.declared_m.has_value();
  const int grid_m = m_declared ? 1 : kGridM;
  std::vector<double> v_grid(grid_m * count);
  for (int b = 0; b < grid_m; ++b) {
    const double m = grid_value(b, grid_m, lower(3), upper(3));
    for (std::size_t i = 0; i < count; ++i)
      v_grid[b * count + i] = s.v_base[i] * std::exp(m * s.log_g[i]);
  }
  // What the cells report of each basis: the data's moments use these, the penalty the bases.
  std::vector<double> tv_grid;
  if (!reported.identity()) {
    tv_grid = v_grid;
    for (int b = 0; b < grid_m; ++b) reported.linear(&tv_grid[b * count]);
  }
  const std::vector<double>& te_all = reported.identity() ? p.e_grid : p.te_grid;
  const std::vector<double>& tv_all = reported.identity() ? v_grid : tv_grid;
  std::vector<double> vv(grid_m), vF(grid_m);
  for (int b = 0; b < grid_m; ++b) {
    for (std::size_t i = 0; i < count; ++i) {
      const double v = tv_all[b * count + i];
      vv[b] += v * v;
      vF[b] += v * s.force[i];
    }
  }
  const std::vector<std::size_t>& unloading = p.unloading;
  std::vector<char> negative(unloading.size());
  Eigen::Vector4d theta = 0.5 * (lower + upper);
  double best_cost = std::numeric_limits<double>::infinity();
  for (int a = 0; a < kGridN; ++a) {
    const double n = grid_value(a, kGridN, lower(1), upper(1));
    const double k_scale = std::exp(s.log_c + n * s.log_ratio);
    const std::span<const double> e(&p.e_grid[a * count], count);
    for (int b = 0; b < grid_m; ++b) {
      const double m = grid_value(b, grid_m, lower(3), upper(3));
      const double d_scale = std::exp(s.log_c + m * s.log_ratio);
      const std::span<const double> v(&v_grid[b * count], count);
      Moments mo{p.ee[a], p.eF[a], vv[b], vF[b], 0.0, p.FF};
      const double* te = &te_all[a * count];
      const double* tv = &tv_all[b * count];
      for (std::size_t i = 0; i < count; ++i) mo.ev += te[i] * tv[i];
      const Coefficients c = best_coefficients(
          mo, e, v, unloading, negative, std::exp(lower(0)) * k_scale, std::exp(upper(0)) * k_scale,
          std::exp(lower(2)) * d_scale, std::exp(upper(2)) * d_scale);
      if (c.cost < best_cost && c.K > 0.0 && c.D > 0.0) {
        best_cost = c.cost;
        theta << std::log(c.K / k_scale), n, std::log(c.D / d_scale), m;
      }
    }
  }
  theta = theta.cwiseMax(lower).cwiseMin(upper);

  // Bounded Levenberg-Marquardt from the best grid point; a step that leaves the box is
  // projected back onto it.
  Solution out;
  Residuals res, trial;
  evaluate(s, reported, theta, res);
  double cost = 0.5 * res.r.squaredNorm();
  double lambda = 1e-3;
  int iterations = 0;
  bool converged = false;
  for (; iterations < settings.max_iterations && !converged; ++iterations) {
    const Eigen::Matrix4d JtJ = res.J.transpose() * res.J;
    const Eigen::Vector4d g = res.J.transpose() * res.r;
    // A parameter at a bound that the gradient pushes outwards is held there (projected
    // Newton): its gradient component does not count, and the step leaves it alone.
    std::array<bool, 4> held{};
    Eigen::Vector4d pg = g;
    for (int k = 0; k < 4; ++k) {
      held[k] = (theta(k) <= lower(k) && g(k) > 0.0) || (theta(k) >= upper(k) && g(k) < 0.0) ||
                (k == 3 && m_declared);
      if (held[k]) pg(k) = 0.0;
    }
    if (pg.lpNorm<Eigen::Infinity>() <= kGradientTolerance * std::max(1.0, cost)) {
      converged = true;
      break;
    }
    bool accepted = false;
    for (int attempt = 0; attempt < 30 && !accepted; ++attempt) {
      Eigen::Matrix4d H = JtJ;
      for (int k = 0; k < 4; ++k) H(k, k) += lambda * std::max(JtJ(k, k), 1e-12);
      for (int k = 0; k < 4; ++k) {
        if (!held[k]) continue;
        H.row(k).setZero();
        H.col(k).setZero();
        H(k, k) = 1.0;
      }
      const Eigen::Vector4d step = H.ldlt().solve(-pg);
      const Eigen::Vector4d next = (theta + step).cwiseMax(lower).cwiseMin(upper);
      evaluate(s, reported, next, trial);
      const double trial_cost = 0.5 * trial.r.squaredNorm();
      if (std::isfinite(trial_cost) && trial_cost <= cost) {
        const double decrease = cost - trial_cost;
        const double moved = (next - theta).norm();
        theta = next;
        std::swap(res, trial);
        converged = decrease <= kFunctionTolerance * cost ||
                    moved <= kParameterTolerance * (theta.norm() + kParameterTolerance);
        cost = trial_cost;
        lambda = std::max(lambda / 3.0, 1e-12);
        accepted = true;
      } else {
        lambda *= 4.0;
      }
    }
    if (!accepted) {
      converged = true;  // no step in any direction lowers the cost: a (bounded) minimum
      break;
    }
  }
  out.theta.assign(static_cast<std::size_t>(layout.size()), 0.0);
  out.theta[static_cast<std::size_t>(iK)] = theta(0);
  out.theta[static_cast<std::size_t>(iN)] = theta(1);
  out.theta[static_cast<std::size_t>(iC)] = theta(2);
  out.theta[static_cast<std::size_t>(iM)] = theta(3);
  out.jacobian = Eigen::MatrixXd(res.J.topRows(static_cast<Eigen::Index>(count)));
  out.iterations = iterations;
  out.cost = cost;
  if (!std::isfinite(cost) || !theta.allFinite()) {
    out.failure = "non_finite";
    out.message = "non-finite cost or parameters";
  } else if (converged) {
    out.converged = true;
    out.message = "grid over (n, m) then Levenberg-Marquardt: converged";
  } else {
    out.failure = "no_convergence";
    out.message = "grid over (n, m) then Levenberg-Marquardt: iteration limit reached";
  }
  return out;
}

// ---- The general fit (free P, seed8): Ceres with automatic derivatives and several starts ----

// The data Jacobian at theta, dense, from Ceres' own evaluation.
Eigen::MatrixXd data_jacobian(ceres::Problem& problem, ceres::ResidualBlockId block,
                              double* theta) {
  ceres::Problem::EvaluateOptions options;
  options.residual_blocks = {block};
  options.parameter_blocks = {theta};
  options.apply_loss_function = false;
  ceres::CRSMatrix crs;
  problem.Evaluate(options, nullptr, nullptr, nullptr, &crs);
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
  for (int r = 0; r < crs.num_rows; ++r) {
    for (int k = crs.rows[static_cast<std::size_t>(r)];
         k < crs.rows[static_cast<std::size_t>(r) + 1]; ++k) {
      J(r, crs.cols[static_cast<std::size_t>(k)]) = crs.values[static_cast<std::size_t>(k)];
    }
  }
  return J;
}

Solution solve_ceres(const std::vector<FitFrame>& frames, const Layout& layout,
                     const FitSettings& settings) {
  const int np = layout.size();
  const ForceModel model{&frames, &layout, settings.model};
  std::vector<double> theta(static_cast<std::size_t>(np));
  ceres::Problem::Options problem_options;
  problem_options.cost_function_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  const int n_res = static_cast<int>(frames.size());
  auto* data_cost =
      new ceres::DynamicAutoDiffCostFunction<DataResidual, 8>(new DataResidual{model});
  data_cost->AddParameterBlock(np);
  data_cost->SetNumResiduals(n_res);
  auto* penalty_cost =
      new ceres::DynamicAutoDiffCostFunction<PenaltyResidual, 8>(new PenaltyResidual{model});
  penalty_cost->AddParameterBlock(np);
  penalty_cost->SetNumResiduals(n_res);
  const ceres::ResidualBlockId data_block =
      problem.AddResidualBlock(data_cost, nullptr, theta.data());
  problem.AddResidualBlock(penalty_cost, nullptr, theta.data());
  for (int i = 0; i < np; ++i) {
    problem.SetParameterLowerBound(theta.data(), i, layout.lower[static_cast<std::size_t>(i)]);
    problem.SetParameterUpperBound(theta.data(), i, layout.upper[static_cast<std::size_t>(i)]);
  }
  ceres::Solver::Options options;
  options.linear_solver_type = ceres::DENSE_QR;
  options.num_threads = 1;
  options.max_num_iterations = settings.max_iterations;
  options.logging_type = ceres::SILENT;
  options.minimizer_progress_to_stdout = false;

  Solution out;
  double best_cost = std::numeric_limits<double>::infinity();
  ceres::Solver::Summary best_summary;
  for (const std::vector<double>& start : initial_guesses(frames, layout, settings)) {
    theta = start;
    ceres::Solver::Summary summary;
    ceres::Solve(options, &problem, &summary);
    if (std::isfinite(summary.final_cost) && summary.final_cost < best_cost) {
      best_cost = summary.final_cost;
      out.theta = theta;
      best_summary = summary;
    }
  }
  if (out.theta.empty()) {
    out.failure = "non_finite";
    out.message = "every start gave a non-finite cost";
    return out;
  }
  theta = out.theta;
  out.jacobian = data_jacobian(problem, data_block, theta.data());
  out.message = best_summary.message;
  out.iterations = best_summary.num_successful_steps + best_summary.num_unsuccessful_steps;
  out.cost = best_summary.final_cost;
  out.converged = best_summary.termination_type == ceres::CONVERGENCE ||
                  best_summary.termination_type == ceres::USER_SUCCESS;
  if (!out.converged) {
    out.failure = best_summary.termination_type == ceres::NO_CONVERGENCE ? "no_convergence"
                                                                         : "solver_failure";
  }
  return out;
}

// Misuse of the fit's inputs, whatever the data.
void check_fit_inputs(const EllipsoidParams& declared, const FitBounds& bounds,
                      const FitSettings& settings) {
  for (const auto& [b, name] : {std::pair{bounds.kbar_n_per_mm3, "kbar_n_per_mm3"},
                                {bounds.n, "n"},
                                {bounds.cbar_ns_per_mm3, "cbar_ns_per_mm3"},
                                {bounds.m, "m"},
                                {bounds.A_mm, "A_mm"},
                                {bounds.B_mm, "B_mm"},
                                {bounds.C_mm, "C_mm"},
                                {bounds.d0_mm, "d0_mm"}}) {
    check_bounds(b, name);
  }
  if (settings.max_iterations < 1) throw std::invalid_argument("max_iterations must be >= 1");
  if (settings.declared_m) {
    if (settings.mode != FitMode::Identifiable || settings.free_scale) {
      throw std::invalid_argument("a declared m needs the default fit (identifiable, P declared)");
    }
    if (!(*settings.declared_m >= bounds.m.lower && *settings.declared_m <= bounds.m.upper)) {
      throw std::invalid_argument("declared m " + std::to_string(*settings.declared_m) +
                                  " is outside the bounds of m");
    }
  }
  if (settings.mode == FitMode::Identifiable) {
    for (double v : {declared.A_mm, declared.B_mm, declared.C_mm, declared.d0_mm}) {
      if (!(v > 0.0) || !std::isfinite(v)) {
        throw std::invalid_argument("declared A, B, C and d0 must be positive and finite");
      }
    }
  }
}

RegionFit fit_frames(const std::vector<FitFrame>& frames, std::size_t input_size,
                     std::span<const double> measured, const EllipsoidParams& declared,
                     const FitBounds& bounds, const FitSettings& settings,
                     const ReportedForce& reported) {
  check_fit_inputs(declared, bounds, settings);
  RegionFit fit;
  fit.frames = static_cast<int>(frames.size());
  fit.model_force_n.assign(input_size, 0.0);
  const Layout layout = make_layout(declared, bounds, settings);
  const int np = layout.size();
  std::array<Estimate*, kPhysCount> est{&fit.A_mm,
                                        &fit.B_mm,
                                        &fit.C_mm,
                                        &fit.d0_mm,
                                        &fit.kbar_n_per_mm3,
                                        &fit.n,
                                        &fit.cbar_ns_per_mm3,
                                        &fit.m};
  {
    const auto values = phys_values(declared);
    for (int p = 0; p < kPhysCount; ++p)
      est[static_cast<std::size_t>(p)]->value = values[static_cast<std::size_t>(p)];
  }
  if (frames.empty()) {
    fit.status = FitStatus::NoContact;
    fit.reason = "no_contact";
    return fit;
  }
  if (static_cast<int>(frames.size()) <= np) {
    fit.status = FitStatus::Failed;
    fit.reason = "too_few_frames";
    return fit;
  }

  const bool separable = settings.mode == FitMode::Identifiable && !settings.free_scale;
  if (!separable && !reported.identity()) {
    throw std::invalid_argument(
        "a ForceTransform needs the default fit (identifiable parameters, P declared)");
  }
  const Solution solution =
      separable ? solve_separable(prepare_separable(frames, layout, settings.model, reported),
                                  layout, settings, reported)
                : solve_ceres(frames, layout, settings);
  if (solution.theta.empty()) {
    fit.status = FitStatus::Failed;
    fit.reason = solution.failure;
    fit.solver_message = solution.message;
    return fit;
  }
  const std::vector<double>& theta = solution.theta;
  fit.solver_message = solution.message;
  fit.iterations = solution.iterations;
  fit.final_cost = solution.cost;

  const ForceModel model{&frames, &layout, settings.model};
  std::vector<double> model_force(frames.size());
  model.forces(theta.data(), model_force.data());
  if (!reported.identity()) {
    reported.linear(model_force.data());
    for (std::size_t i = 0; i < frames.size(); ++i) model_force[i] += reported.offset()[i];
  }
  std::vector<double> fitted_measured(frames.size());
  double ssr = 0.0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    fit.model_force_n[frames[i].input_index] = model_force[i];
    fitted_measured[i] = measured[frames[i].input_index];
    ssr += (model_force[i] - frames[i].force_n) * (model_force[i] - frames[i].force_n);
  }
  fit.nrmse_pct = nrmse_pct(fitted_measured, model_force);

  // Standard errors: sigma^2 (J^T J)^-1 over the columns the data determine, taken in order so
  // that a dependent parameter is named after the ones it trades off against.
  const Eigen::MatrixXd& J = solution.jacobian;
  const int n_res = static_cast<int>(frames.size());
  std::vector<int> kept;
  Eigen::MatrixXd basis(J.rows(), 0);
  std::vector<bool> dependent(static_cast<std::size_t>(np), false);
  const int declared_column = settings.declared_m ? layout.index[kM] : -1;
  for (int c = 0; c < np; ++c) {
    if (c == declared_column) continue;
    const double norm = J.col(c).norm();
    if (!(norm > 0.0)) {
      dependent[static_cast<std::size_t>(c)] = true;
      continue;
    }
    Eigen::VectorXd v = J.col(c) / norm;
    for (Eigen::Index k = 0; k < basis.cols(); ++k) v -= basis.col(k).dot(v) * basis.col(k);
    for (Eigen::Index k = 0; k < basis.cols(); ++k) v -= basis.col(k).dot(v) * basis.col(k);
    if (v.norm() < kDependentColumn) {
      dependent[static_cast<std::size_t>(c)] = true;
      continue;
    }
    basis.conservativeResize(Eigen::NoChange, basis.cols() + 1);
    basis.col(basis.cols() - 1) = v / v.norm();
    kept.push_back(c);
  }
  std::vector<double> se_theta(static_cast<std::size_t>(np),
                               std::numeric_limits<double>::infinity());
  const int dof = n_res - static_cast<int>(kept.size());
  if (dof > 0 && !kept.empty()) {
    Eigen::MatrixXd Jk(J.rows(), static_cast<Eigen::Index>(kept.size()));
    for (std::size_t k = 0; k < kept.size(); ++k)
      Jk.col(static_cast<Eigen::Index>(k)) = J.col(kept[k]);
    const double sigma2 = ssr / dof;
    const Eigen::MatrixXd cov =
        sigma2 *
        (Jk.transpose() * Jk).ldlt().solve(Eigen::MatrixXd::Identity(Jk.cols(), Jk.cols()));
    // With m declared its row and column stay zero: the covariance of the others at that m.
    const std::size_t material = settings.declared_m ? 3 : 4;
    if (settings.mode == FitMode::Identifiable && layout.log_p < 0 && kept.size() == material) {
      MaterialCovariance c{};
      for (std::size_t a = 0; a < material; ++a) {
        for (std::size_t b = 0; b < material; ++b) {
          c[a][b] = cov(static_cast<Eigen::Index>(a), static_cast<Eigen::Index>(b));
        }
      }
      fit.material_covariance = c;
      if (settings.declared_m) {
        const Eigen::Vector3d slope =
            -(Jk.transpose() * Jk).ldlt().solve(Jk.transpose() * J.col(declared_column));
        fit.material_slope_on_m = std::array<double, 3>{slope(0), slope(1), slope(2)};
      }
    }
    for (std::size_t k = 0; k < kept.size(); ++k) {
      const double var = cov(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(k));
      se_theta[static_cast<std::size_t>(kept[k])] =
          var >= 0.0 ? std::sqrt(var) : std::numeric_limits<double>::infinity();
    }
  }
  for (int c = 0; c < np; ++c) {
    if (c == declared_column) continue;
    if (dependent[static_cast<std::size_t>(c)] ||
        !std::isfinite(se_theta[static_cast<std::size_t>(c)])) {
      fit.undetermined.push_back(layout.names[static_cast<std::size_t>(c)]);
    }
  }

  const auto at_bound = [](double v, double lo, double hi) {
    return std::abs(v - lo) <= kBoundTolerance * std::abs(lo) ||
           std::abs(v - hi) <= kBoundTolerance * std::abs(hi);
  };
  const auto pb = phys_bounds(bounds);
  for (int p = 0; p < kPhysCount; ++p) {
    const int i = layout.index[static_cast<std::size_t>(p)];
    if (i < 0) continue;
    Estimate& e = *est[static_cast<std::size_t>(p)];
    const double t = theta[static_cast<std::size_t>(i)];
    e.value = is_log(p) ? std::exp(t) : t;
    e.se = is_log(p) ? e.value * se_theta[static_cast<std::size_t>(i)]
                     : se_theta[static_cast<std::size_t>(i)];
    e.free = i != declared_column;
    if (!e.free) e.se = 0.0;
    e.at_bound = at_bound(e.value, pb[static_cast<std::size_t>(p)].lower,
                          pb[static_cast<std::size_t>(p)].upper);
  }
  if (layout.log_p >= 0) {
    // P = pi A B with A/B kept: A and B each scale as sqrt(P).
    const double P = std::exp(theta[static_cast<std::size_t>(layout.log_p)]);
    const double ratio = declared.A_mm / declared.B_mm;
    const double se_half = 0.5 * se_theta[static_cast<std::size_t>(layout.log_p)];
    const bool bound = at_bound(P, std::exp(layout.lower[static_cast<std::size_t>(layout.log_p)]),
                                std::exp(layout.upper[static_cast<std::size_t>(layout.log_p)]));
    fit.A_mm = {std::sqrt(P * ratio / std::numbers::pi), 0.0, bound, true};
    fit.B_mm = {std::sqrt(P / (ratio * std::numbers::pi)), 0.0, bound, true};
    fit.A_mm.se = fit.A_mm.value * se_half;
    fit.B_mm.se = fit.B_mm.value * se_half;
  }

  if (solution.converged) {
    fit.status = FitStatus::Ok;
  } else {
    fit.status = FitStatus::Failed;
    fit.reason = solution.failure;
  }
  return fit;
}

void check_series(const RegionSeries& s) {
  if (s.area_mm2.size() != s.t_s.size() || s.force_n.size() != s.t_s.size()) {
    throw std::invalid_argument("RegionSeries: t_s, area_mm2 and force_n differ in length");
  }
}

}  // namespace

namespace detail {

SeparableResiduals separable_residuals(const RegionSeries& series, const EllipsoidParams& declared,
                                       const FitSettings& settings,
                                       const std::array<double, 4>& theta) {
  check_series(series);
  std::vector<FitFrame> frames;
  append_frames(series, settings.smoothing, settings.end_rate, 0, frames);
  Layout layout;
  layout.declared = phys_values(declared);
  const ReportedForce none(frames, {}, {}, series.t_s.size());
  Residuals res;
  evaluate(separable_data(frames, layout, settings.model, none.offset()), none,
           Eigen::Vector4d(theta[0], theta[1], theta[2], theta[3]), res);
  SeparableResiduals out;
  out.residual.assign(res.r.begin(), res.r.end());
  for (Eigen::Index row = 0; row < res.J.rows(); ++row) {
    out.jacobian.push_back({res.J(row, 0), res.J(row, 1), res.J(row, 2), res.J(row, 3)});
  }
  return out;
}

}  // namespace detail

RegionFit fit_region(const RegionSeries& series, const EllipsoidParams& declared,
                     const FitBounds& bounds, const FitSettings& settings,
                     const ForceTransform* transform) {
  const std::array<const ForceTransform*, 1> transforms{transform};
  return fit_region_session(std::span<const RegionSeries>(&series, 1), declared, bounds, settings,
                            transform != nullptr
                                ? std::span<const ForceTransform* const>(transforms)
                                : std::span<const ForceTransform* const>());
}

RegionFit fit_region_session(std::span<const RegionSeries> stances, const EllipsoidParams& declared,
                             const FitBounds& bounds, const FitSettings& settings,
                             std::span<const ForceTransform* const> transforms) {
  if (!transforms.empty() && transforms.size() != stances.size()) {
    throw std::invalid_argument("fit_region_session: one ForceTransform (or none) per stance");
  }
  std::vector<FitFrame> frames;
  std::vector<double> measured;
  std::vector<std::size_t> stance_begin;
  for (const RegionSeries& s : stances) {
    check_series(s);
    stance_begin.push_back(measured.size());
    append_frames(s, settings.smoothing, settings.end_rate, measured.size(), frames);
    measured.insert(measured.end(), s.force_n.begin(), s.force_n.end());
  }
  const ReportedForce reported(frames, stance_begin, transforms, measured.size());
  return fit_frames(frames, measured.size(), measured, declared, bounds, settings, reported);
}

std::optional<SharedExponent> fit_shared_damping_exponent(std::span<const RegionSeries> stances,
                                                          std::span<const EllipsoidParams> declared,
                                                          const FitBounds& bounds,
                                                          const FitSettings& settings) {
  if (stances.size() != declared.size()) {
    throw std::invalid_argument("fit_shared_damping_exponent: one declared set per stance");
  }
  if (settings.mode != FitMode::Identifiable || settings.free_scale) {
    throw std::invalid_argument("a shared m needs the default fit (identifiable, P declared)");
  }
  check_bounds(bounds.m, "m");
  // Each stance prepared once (its frames and the elastic bases over n), then solved at every m
  // tried: its cost there, nothing where its fit fails as fit_region's would.
  struct Prepared {
    std::vector<FitFrame> frames;
    Layout layout;
    SeparableProblem problem;
  };
  std::vector<Prepared> prepared(stances.size());
  FitSettings at = settings;
  at.declared_m = bounds.m.lower;
  for (std::size_t i = 0; i < stances.size(); ++i) {
    check_series(stances[i]);
    check_fit_inputs(declared[i], bounds, at);
    Prepared& p = prepared[i];
    append_frames(stances[i], settings.smoothing, settings.end_rate, 0, p.frames);
    p.layout = make_layout(declared[i], bounds, at);
    const ReportedForce none(p.frames, {}, {}, stances[i].t_s.size());
    p.problem = prepare_separable(p.frames, p.layout, settings.model, none);
  }
  const auto cost_at = [&](std::size_t i, double m) -> std::optional<double> {
    Prepared& p = prepared[i];
    if (p.frames.size() <= static_cast<std::size_t>(p.layout.size())) return std::nullopt;
    const auto im = static_cast<std::size_t>(p.layout.index[kM]);
    p.layout.lower[im] = p.layout.upper[im] = m;
    at.declared_m = m;
    const ReportedForce none(p.frames, {}, {}, stances[i].t_s.size());
    const Solution solution = solve_separable(p.problem, p.layout, at, none);
    if (solution.theta.empty() || !solution.converged) return std::nullopt;
    return solution.cost;
  };
  const double lo = bounds.m.lower, hi = bounds.m.upper;
  std::vector<double> grid(kGridM);
  for (std::size_t j = 0; j < grid.size(); ++j) {
    grid[j] = lo + (hi - lo) * static_cast<double>(j) / static_cast<double>(grid.size() - 1);
  }
  // The stances fitted at every grid point, and their summed cost there.
  std::vector<std::size_t> kept;
  std::vector<double> grid_total(grid.size(), 0.0);
  for (std::size_t i = 0; i < stances.size(); ++i) {
    std::vector<double> costs;
    for (double m : grid) {
      const auto c = cost_at(i, m);
      if (!c) break;
      costs.push_back(*c);
    }
    if (costs.size() < grid.size()) continue;
    kept.push_back(i);
    for (std::size_t j = 0; j < grid.size(); ++j) grid_total[j] += costs[j];
  }
  if (kept.empty()) return std::nullopt;
  // Off the grid, a stance that fails makes that m unusable: a cost beyond any real one, finite
  // so that Brent's parabolas through it stay numbers.
  const auto summed = [&](double m) {
    double total = 0.0;
    for (std::size_t i : kept) {
      const auto c = cost_at(i, m);
      if (!c) return kUnusableCost;
      total += *c;
    }
    return total;
  };
  const auto best = static_cast<std::size_t>(
      std::min_element(grid_total.begin(), grid_total.end()) - grid_total.begin());
  // Brent's method (parabolic steps, golden sections where they fail) between the best grid
  // point's neighbours, to about 0.001 in m.
  std::uintmax_t max_evaluations = kMaxBrentEvaluations;
  const auto [searched, searched_cost] = boost::math::tools::brent_find_minima(
      summed, grid[best == 0 ? 0 : best - 1], grid[std::min(best + 1, grid.size() - 1)], kBrentBits,
      max_evaluations);
  SharedExponent out;
  out.stances = static_cast<int>(kept.size());
  // The grid point itself can be lower than where the search ends (a minimum at a bound).
  const bool search_lower = searched_cost <= grid_total[best];
  out.m = search_lower ? searched : grid[best];
  const double f0 = search_lower ? searched_cost : grid_total[best];
  out.at_bound = std::abs(out.m - lo) <= kBoundTolerance * std::abs(lo) ||
                 std::abs(out.m - hi) <= kBoundTolerance * std::abs(hi);
  // The summed cost is half the squared residuals, so its second derivative along m, the others
  // fitted again, is J^T J there: over steps of h, inward at a bound.
  const double h = 0.01;
  double curvature = 0.0;
  if (out.m - h >= lo && out.m + h <= hi) {
    curvature = (summed(out.m + h) - 2.0 * f0 + summed(out.m - h)) / (h * h);
  } else {
    const double inward = out.m - h < lo ? h : -h;
    curvature = (f0 - 2.0 * summed(out.m + inward) + summed(out.m + 2.0 * inward)) / (h * h);
  }
  // The residuals' variance: each stance's frames less its three parameters, and m.
  std::size_t frames = 0;
  for (std::size_t i : kept) frames += prepared[i].frames.size();
  const int dof = static_cast<int>(frames) - 3 * static_cast<int>(kept.size()) - 1;
  const double sigma2 = dof > 0 ? 2.0 * f0 / dof : 0.0;
  out.se = curvature > 0.0 && sigma2 > 0.0 ? std::sqrt(sigma2 / curvature)
                                           : std::numeric_limits<double>::infinity();
  return out;
}

}  // namespace gaitmon
