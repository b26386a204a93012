// The candidate effects of the discrepancy workflow: each transforms the baseline's force of a
// unit with its shared parameters fixed (tissue memory, hysteresis, heel impact, cell ceiling,
// sensor creep, thermal drift, crosstalk).
#include "discrepancy_effects.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <optional>
#include <utility>

namespace gaitmon::discrepancy_detail {
namespace {

constexpr double kPi = std::numbers::pi;

// The foot's measured force of one region, low-passed through its steps: the lag carried into
// each unit from the earlier ones (decayed over the swing) and the lag at each unit's end.
struct CarriedLag {
  std::vector<double> r0, r_end;
};

CarriedLag carried_lag(const std::vector<Unit>& units, double tau_s) {
  std::vector<double> r0(units.size(), 0.0);
  std::vector<double> r_end(units.size(), 0.0);
  std::vector<std::size_t> order(units.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return units[a].t.front() < units[b].t.front();
  });
  for (std::size_t ui : order) {
    const Unit& u = units[ui];
    if (u.prev >= 0) {
      const Unit& p = units[static_cast<std::size_t>(u.prev)];
      const double gap = (u.t.front() - u.dt_s) - p.t.back();
      r0[ui] = r_end[static_cast<std::size_t>(u.prev)] * std::exp(-std::max(0.0, gap) / tau_s);
    }
    const double keep = std::exp(-u.dt_s / tau_s);
    double r = r0[ui];
    for (double v : u.y) r = r * keep + v * (1.0 - keep);
    r_end[ui] = r;
  }
  return {std::move(r0), std::move(r_end)};
}

// The lag's mean over a unit's two zero windows: it decays from the end of the unit before to
// the window before the step, and from the unit's own end to the window after it (`level`);
// and that of a unit lag at its chain's first window, decayed (`per_start_lag`: the lag is
// linear, so an unknown start adds that times its size). 0 where a window's time is unknown.
struct ZeroWindowLag {
  std::vector<double> level, per_start_lag;
};

ZeroWindowLag lag_in_zero_windows(const std::vector<Unit>& units, const CarriedLag& lag,
                                  double tau_s) {
  ZeroWindowLag out{std::vector<double>(units.size(), 0.0), std::vector<double>(units.size(), 0.0)};
  for (std::size_t ui = 0; ui < units.size(); ++ui) {
    const Unit& u = units[ui];
    if (u.chain < 0) continue;
    double before = 0.0;
    if (u.prev >= 0) {
      const auto p = static_cast<std::size_t>(u.prev);
      before = lag.r_end[p] * std::exp(-std::max(0.0, u.t_pre_zero_s - units[p].t.back()) / tau_s);
    }
    const double after =
        lag.r_end[ui] * std::exp(-std::max(0.0, u.t_post_zero_s - u.t.back()) / tau_s);
    out.level[ui] = 0.5 * (before + after);
    const double t0 = units[static_cast<std::size_t>(u.chain)].t_pre_zero_s;
    out.per_start_lag[ui] = 0.5 * (std::exp(-(u.t_pre_zero_s - t0) / tau_s) +
                                   std::exp(-(u.t_post_zero_s - t0) / tau_s));
  }
  return out;
}

// F + gain x F low-passed: stress relaxation in the tissue (gain < 0) or creep of the sensor
// (gain > 0). A sensor also reads its lag without a load, in the swing windows the segmenter
// takes each step's zero from, and the zero channel sees that. A step zeroed at those windows
// has the creep's level taken off its stance; the rise within one stance that is left is about
// proportional to the load and the step's own stiffness takes it up, so the sensor's stance
// force is left to the baseline there. (Modelled as gain x (lag - its mean in the windows), it
// made the held-out force error of a creep session worse by 6-12 % at the true gain and tau.)
class LagEffect final : public Applied {
 public:
  enum class Stage : std::uint8_t { Tissue, Sensor };
  LagEffect(const std::vector<Unit>& units, double sign_gain, double tau_s, Stage stage)
      : gain_(sign_gain), tau_s_(tau_s), sensor_(stage == Stage::Sensor) {
    const CarriedLag lag = carried_lag(units, tau_s);
    r0_ = lag.r0;
    if (sensor_) zero_lag_ = lag_in_zero_windows(units, lag, tau_s);
  }
  bool affects(const Unit& u) const override { return gain_ != 0.0 && !(sensor_ && zeroed(u)); }
  void apply(std::size_t ui, const Unit& u, std::span<const double> F, std::span<double> out,
             std::size_t /*choice*/) const override {
    double r = r0_[ui];
    for (std::size_t i = 0; i < F.size(); ++i) {
      const double keep = std::exp(-(i > 0 ? u.t[i] - u.t[i - 1] : u.dt_s) / tau_s_);
      r = r * keep + F[i] * (1.0 - keep);
      out[i] = F[i] + gain_ * r;
    }
  }
  double swing_reading(std::size_t ui) const override {
    return sensor_ ? gain_ * zero_lag_.level[ui] : 0.0;
  }
  double swing_reading_per_start_lag(std::size_t ui) const override {
    return sensor_ ? gain_ * zero_lag_.per_start_lag[ui] : 0.0;
  }

 private:
  static bool zeroed(const Unit& u) {
    return std::isfinite(u.t_pre_zero_s) && std::isfinite(u.t_post_zero_s);
  }
  double gain_;
  double tau_s_;
  bool sensor_;
  std::vector<double> r0_;
  ZeroWindowLag zero_lag_;
};

class HysteresisEffect final : public Applied {
 public:
  HysteresisEffect(double h, double transition_mm) : h_(h), transition_mm_(transition_mm) {}
  bool affects(const Unit&) const override { return h_ != 0.0; }
  void apply(std::size_t, const Unit& u, std::span<const double> F, std::span<double> out,
             std::size_t /*choice*/) const override {
    // Each contact starts from the unloaded state the previous one left: z = -1 at d = 0.
    double z = -1.0;
    double d_prev = 0.0;
    for (std::size_t i = 0; i < F.size(); ++i) {
      const double step = u.d_mm[i] - d_prev;
      if (step != 0.0) {
        const double target = step > 0.0 ? 1.0 : -1.0;
        z = target + (z - target) * std::exp(-std::abs(step) / transition_mm_);
        d_prev = u.d_mm[i];
      }
      out[i] = F[i] * (1.0 + h_ * z);
    }
  }

 private:
  double h_;
  double transition_mm_;
};

// The pulse starts at the heel's contact, which falls anywhere between two frames and may read
// under the threshold for a frame or two: its onset before the heel's first frame with a load
// is a property of each step, chosen by each step's fit from 0 to 2 frames in tenths. As one
// shared value (0, 0.5 or 1 frame) it left the weakest impact of the matrix (80 N over 30 ms,
// three frames) explaining 15 % of its gap at the simulator's own amplitude and duration.
class ImpactEffect final : public Applied {
 public:
  static constexpr std::size_t kOnsetChoices = 21;
  static constexpr double kOnsetStepFrames = 0.1;
  ImpactEffect(double amplitude_n, double duration_s) : a_(amplitude_n), T_(duration_s) {}
  bool affects(const Unit& u) const override { return u.region == Region::Heel && a_ != 0.0; }
  std::size_t choices(const Unit& u) const override {
    return u.region == Region::Heel ? kOnsetChoices : 1;
  }
  bool additive() const override { return true; }
  void apply(std::size_t, const Unit& u, std::span<const double> F, std::span<double> out,
             std::size_t choice) const override {
    const double t0 = u.t_contact_s - static_cast<double>(choice) * kOnsetStepFrames * u.dt_s;
    for (std::size_t i = 0; i < F.size(); ++i) {
      const double tau = u.t[i] - t0;
      out[i] = F[i];
      if (u.region == Region::Heel && tau > 0.0 && tau < T_)
        out[i] += a_ * std::sin(kPi * tau / T_);
    }
  }

 private:
  double a_;
  double T_;
};

// A cell at the ceiling c reads c however hard it is pressed, so over a contact whose paraboloid
// pressure peaks at p0 > c the cells read the paraboloid capped at c: the force falls short by
// the fraction L^2, L = 1 - c / p0 (the capped share of the squared radius). The measured
// footprint is fitted to those capped readings, and a paraboloid fitted to a flat top is wider:
// least squares of a + b s (s the squared radius over the contact's, uniform in area) over the
// cap it covers, iterated as footprint_area_unthresholded_mm2 does, settles where the area is
// phi(L) = (1 + L + L^2) / (1 + L) times the contact's (tests/discrepancy_test.cpp checks it
// against the footprint code on a capped raster). The model force at the measured area is
// then the contact's times phi^(2 + n) (E ~ A^(2 + n) for a shallow contact; n = 0.3 here, the
// candidate sees the force, not the unit's n), and the pressure computed from it, p_m = 2 F / A
// in readings, is p0 phi^(1 + n). Without the footprint's bias the ceiling came out 10-30 % low
// (98.8, 73.8 and 42.5 bits where the simulator's cells stopped at 110, 85 and 60).
class SaturationEffect final : public Applied {
 public:
  // A paraboloid pressure over the contact peaks at twice its mean, so the peak reading is
  // p = 2 F / (newtons_per_bit x cells in contact), and q = c / p = q_scale_ x area / F.
  SaturationEffect(double ceiling_bits, double cell_area_mm2, double newtons_per_bit)
      : q_scale_(ceiling_bits * newtons_per_bit / (2.0 * cell_area_mm2)) {}
  bool affects(const Unit&) const override { return true; }
  bool affine() const override { return false; }
  void apply(std::size_t, const Unit& u, std::span<const double> F, std::span<double> out,
             std::size_t /*choice*/) const override {
    const std::vector<double>& table = fraction_table();
    for (std::size_t i = 0; i < F.size(); ++i) {
      out[i] = F[i];
      if (!(u.area[i] > 0.0) || !(F[i] > 0.0)) continue;
      out[i] = F[i] * measured_fraction(table, q_scale_ * u.area[i] / F[i]).value;
    }
  }
  // With f the fraction and q = q_scale area / F: d(F f(q))/dF = f - q f'(q).
  bool apply_with_slope(std::size_t, const Unit& u, std::span<const double> F,
                        std::span<double> out, std::span<double> slope) const override {
    const std::vector<double>& table = fraction_table();
    for (std::size_t i = 0; i < F.size(); ++i) {
      out[i] = F[i];
      slope[i] = 1.0;
      if (!(u.area[i] > 0.0) || !(F[i] > 0.0)) continue;
      const double q = q_scale_ * u.area[i] / F[i];
      const Fraction f = measured_fraction(table, q);
      out[i] = F[i] * f.value;
      slope[i] = f.value - q * f.per_q;
    }
    return true;
  }

 private:
  struct Fraction {
    double value = 1.0, per_q = 0.0;
  };
  /// The force the cells read over the model's force at the measured footprint, given
  /// q = c / p_m: phi^-(2 + n) (1 - L^2) with L = 1 - q phi(L)^(1 + n), 1 where q >= 1;
  /// interpolated linearly in a table of q in [0, 1], with that segment's slope.
  static Fraction measured_fraction(const std::vector<double>& table, double q) {
    if (!(q < 1.0)) return {};
    const double scale = static_cast<double>(kTablePoints - 1);
    const double x = std::max(q, 0.0) * scale;
    const auto k = std::min(static_cast<std::size_t>(x), kTablePoints - 2);
    const double w = x - static_cast<double>(k);
    return {(1.0 - w) * table[k] + w * table[k + 1], (table[k + 1] - table[k]) * scale};
  }
  static const std::vector<double>& fraction_table() {
    static const std::vector<double> table = [] {
      std::vector<double> t(kTablePoints);
      for (std::size_t k = 0; k < kTablePoints; ++k) t[k] = solve_fraction(q_of(k));
      return t;
    }();
    return table;
  }

  static constexpr std::size_t kTablePoints = 2001;
  static constexpr double kExponentN = 0.3;
  static double q_of(std::size_t k) {
    return static_cast<double>(k) / static_cast<double>(kTablePoints - 1);
  }
  static double phi(double L) { return (1.0 + L + L * L) / (1.0 + L); }
  static double solve_fraction(double q) {
    // L = 1 - q phi(L)^(1 + n) is a contraction (slope below 0.7 for q <= 1): fixed point.
    double L = 1.0 - q;
    for (int it = 0; it < 60; ++it) L = std::max(0.0, 1.0 - q * std::pow(phi(L), 1.0 + kExponentN));
    return std::pow(phi(L), -(2.0 + kExponentN)) * (1.0 - L * L);
  }
  double q_scale_;
};

// Every cell's unloaded reading drifting at one rate as the insole warms to the foot (or cools):
// a region's zero moves by its cell count times the drift between the two steps' zero windows.
// Linear in time: warm-up time constants are minutes, and over a session of that length only
// the mean rate is left once the zeros' noise is in. The stance force is zeroed at the windows
// on both sides, which takes a linear drift off it exactly (the step's zero is their mean, the
// drift at mid-stance), so the force is left to the baseline; with one window only, the stance
// is off by the drift since that window, a few hundredths of a bit per cell in contact at 4
// bits a minute, under the force's noise.
class ThermalDriftEffect final : public Applied {
 public:
  ThermalDriftEffect(const std::vector<Unit>& units, double rate_bits_per_min,
                     double newtons_per_bit)
      : level_(units.size(), 0.0) {
    const double n_per_cell_s = rate_bits_per_min / 60.0 * newtons_per_bit;
    for (std::size_t ui = 0; ui < units.size(); ++ui) {
      const Unit& u = units[ui];
      if (!std::isfinite(u.t_pre_zero_s) || !std::isfinite(u.t_post_zero_s)) continue;
      level_[ui] = n_per_cell_s * u.cells * 0.5 * (u.t_pre_zero_s + u.t_post_zero_s);
    }
  }
  bool affects(const Unit&) const override { return false; }
  void apply(std::size_t, const Unit&, std::span<const double> F, std::span<double> out,
             std::size_t /*choice*/) const override {
    std::copy(F.begin(), F.end(), out.begin());
  }
  double swing_reading(std::size_t ui) const override { return level_[ui]; }

 private:
  std::vector<double> level_;
};

// Each cell also reads a share k of what the cells it shares an edge with read. That reaches the
// model through the area as well as the force: the cells around a contact read their neighbours'
// share, and the footprint fitted to the readings widens, most where the contact is small. So
// the steps were measured again with the readings corrected at couplings of kCrosstalkGrid
// (CrosstalkCorrection, measure_crosstalk_views), and at k the unit's area, its corrected force
// and what its cells read of other regions' cells (the spill) are interpolated between them. The
// model is driven by the corrected area and predicts the corrected force. What the region's cells
// read of each other grows with that load, so the measured force is the model's times the gain
// (measured - spill) / corrected, plus the spill, another region's load: the residual is on the
// measured force's scale. (Predicting the measured force as the model's plus all the correction
// took off left it on the corrected force's: a correction that only shrank every force by c
// lowered the squared error by c^2 and looked like a gain.) The price is a bias the other way:
// the model's own misfit reaches the residual times the gain, which grows with k, and where the
// misfit is flat near the truth the fitted coupling comes out low (README). Where the cells at or
// above the threshold differ between the readings and their correction, the gain can come out
// beyond what mixing gives (1 + 4 k) or the corrected force at 0; the gain is then held to [0, 1 +
// 4 k], a frame with nothing corrected left takes the nearest frame's (as crosstalk_series does for
// the area), and the rest of the measured force is added, so that the prediction is the measured
// force wherever the model is the corrected force.
class CrosstalkEffect final : public Applied {
 public:
  CrosstalkEffect(const std::vector<Unit>& units, double coupling)
      : k_(coupling), seen_(units.size()), gain_(units.size()), spill_(units.size()) {
    if (k_ == 0.0) return;
    const auto hi = std::upper_bound(kCrosstalkGrid.begin(), kCrosstalkGrid.end(), k_);
    const std::size_t g1 = std::clamp<std::size_t>(
        static_cast<std::size_t>(hi - kCrosstalkGrid.begin()), 1, kCrosstalkGrid.size() - 1);
    // Below the grid's first coupling the uncorrected series (k = 0) is the other end.
    const bool from_zero = k_ < kCrosstalkGrid.front();
    const double k0 = from_zero ? 0.0 : kCrosstalkGrid[g1 - 1];
    const double k1 = from_zero ? kCrosstalkGrid.front() : kCrosstalkGrid[g1];
    const double w = std::clamp((k_ - k0) / (k1 - k0), 0.0, 1.0);
    // A cell's edge shares add up to 4 at most (InsoleLayout::neighbours), so mixing raises a
    // region's own load by 4 k at most.
    const double max_gain = 1.0 + 4.0 * k_;
    const auto between = [&](const std::vector<std::vector<double>>& at, std::size_t i,
                             double at_zero) {
      const double lo = from_zero ? at_zero : at[g1 - 1][i];
      return (1.0 - w) * lo + w * at[from_zero ? 0 : g1][i];
    };
    std::vector<double> area, corrected;
    for (std::size_t ui = 0; ui < units.size(); ++ui) {
      const Unit& u = units[ui];
      if (!affects(u)) continue;
      const CrosstalkSeries& x = *u.crosstalk;
      const std::size_t n = u.y.size();
      area.resize(n);
      gain_[ui].resize(n);
      spill_[ui].resize(n);
      corrected.resize(n);
      std::vector<double>& gain = gain_[ui];
      for (std::size_t i = 0; i < n; ++i) {
        area[i] = between(x.area_mm2, i, u.area[i]);
        corrected[i] = u.y[i] - between(x.removed_n, i, 0.0);
        const double spill = between(x.spill_in_n, i, 0.0);
        gain[i] = corrected[i] > 0.0 ? std::clamp((u.y[i] - spill) / corrected[i], 0.0, max_gain)
                                     : std::numeric_limits<double>::quiet_NaN();
      }
      fill_from_nearest(gain, 1.0);
      for (std::size_t i = 0; i < n; ++i) spill_[ui][i] = u.y[i] - gain[i] * corrected[i];
      // The tissue's and the cells' effects act on the contact the corrected readings give.
      Shapes sh = shapes_of(u.t, area, u.shape_model);
      Unit& v = seen_[ui].emplace(u);
      v.area = area;
      v.E = sh.En.front();
      v.En = std::move(sh.En);
      v.V = std::move(sh.V);
      v.d_mm = std::move(sh.d_mm);
      v.ddot_mm_per_s = std::move(sh.ddot_mm_per_s);
    }
  }
  bool affects(const Unit& u) const override {
    return k_ != 0.0 && u.crosstalk != nullptr &&
           u.crosstalk->area_mm2.size() == kCrosstalkGrid.size() &&
           u.crosstalk->removed_n.size() == kCrosstalkGrid.size() &&
           u.crosstalk->spill_in_n.size() == kCrosstalkGrid.size();
  }
  void apply(std::size_t ui, const Unit&, std::span<const double> F, std::span<double> out,
             std::size_t /*choice*/) const override {
    const std::vector<double>& gain = gain_[ui];
    const std::vector<double>& spill = spill_[ui];
    for (std::size_t i = 0; i < F.size(); ++i) {
      out[i] = i < gain.size() ? F[i] * gain[i] + spill[i] : F[i];
    }
  }
  const Unit* seen(std::size_t ui) const override { return seen_[ui] ? &*seen_[ui] : nullptr; }

 private:
  double k_;
  std::vector<std::optional<Unit>> seen_;
  std::vector<std::vector<double>> gain_, spill_;
};

std::vector<double> linspace(double lo, double hi, int n) {
  std::vector<double> v;
  for (int i = 0; i < n; ++i) v.push_back(lo + (hi - lo) * i / (n - 1));
  return v;
}

}  // namespace

void fill_from_nearest(std::vector<double>& v, double otherwise) {
  const std::vector<double> given = v;
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (!std::isnan(given[i])) continue;
    v[i] = otherwise;
    for (std::size_t d = 1; d < v.size(); ++d) {
      const bool before = i >= d && !std::isnan(given[i - d]);
      const bool after = i + d < v.size() && !std::isnan(given[i + d]);
      if (before || after) {
        v[i] = after ? given[i + d] : given[i - d];
        break;
      }
    }
  }
}

std::vector<CandidateSpec> candidate_specs(double cell_area_mm2, double newtons_per_bit) {
  // Coarse grids (the local refinement takes the parameters between the points): time
  // constants log-spaced over the physically plausible ranges.
  const std::vector<double> fast_tau{0.02, 0.05, 0.1, 0.2, 0.4, 0.8, 1.6, 3.0};
  const std::vector<double> slow_tau{0.1, 0.25, 0.5, 1.0, 2.0, 4.0, 10.0};
  std::vector<CandidateSpec> specs;
  specs.push_back(
      {"stress_relaxation",
       0,
       {{"strength", 0.0, 0.95, linspace(0.07, 0.7, 10)}, {"tau_s", 0.005, 10.0, fast_tau}},
       [](const std::vector<Unit>& units, std::span<const double> th) {
         return std::make_unique<LagEffect>(units, -th[0], th[1], LagEffect::Stage::Tissue);
       }});
  specs.push_back({"hysteresis",
                   0,
                   {{"strength", 0.0, 0.9, linspace(0.04, 0.4, 10)},
                    {"transition_mm", 0.005, 10.0, {0.05, 0.12, 0.3, 0.7, 2.0}}},
                   [](const std::vector<Unit>&, std::span<const double> th) {
                     return std::make_unique<HysteresisEffect>(th[0], th[1]);
                   }});
  specs.push_back({"impact_transient",
                   0,
                   {{"amplitude_n", 0.0, 1000.0, linspace(10.0, 250.0, 9)},
                    {"duration_s", 0.005, 0.2, linspace(0.02, 0.1, 5)}},
                   [](const std::vector<Unit>&, std::span<const double> th) {
                     return std::make_unique<ImpactEffect>(th[0], th[1]);
                   }});
  specs.push_back(
      {"sensor_saturation",
       1,
       {{"ceiling_bits", 5.0, 1000.0, linspace(40.0, 260.0, 12)}},
       [cell_area_mm2, newtons_per_bit](const std::vector<Unit>&, std::span<const double> th) {
         return std::make_unique<SaturationEffect>(th[0], cell_area_mm2, newtons_per_bit);
       },
       false,
       true});
  specs.push_back({"sensor_creep",
                   1,
                   {{"gain", 0.0, 2.0, linspace(0.05, 0.5, 10)}, {"tau_s", 0.02, 60.0, slow_tau}},
                   [](const std::vector<Unit>& units, std::span<const double> th) {
                     return std::make_unique<LagEffect>(units, th[0], th[1],
                                                        LagEffect::Stage::Sensor);
                   },
                   true});
  specs.push_back(
      {"thermal_drift",
       1,
       {{"rate_bits_per_min", -200.0, 200.0, {-16, -8, -4, -2, -1, -0.5, 0, 0.5, 1, 2, 4, 8, 16}}},
       [newtons_per_bit](const std::vector<Unit>& units, std::span<const double> th) {
         return std::make_unique<ThermalDriftEffect>(units, th[0], newtons_per_bit);
       }});
  specs.push_back({std::string(kCrosstalk),
                   2,
                   {{"coupling", 0.0, kCrosstalkGrid.back(),
                     std::vector<double>(kCrosstalkGrid.begin(), kCrosstalkGrid.end())}},
                   [](const std::vector<Unit>& units, std::span<const double> th) {
                     return std::make_unique<CrosstalkEffect>(units, th[0]);
                   }});
  return specs;
}

}  // namespace gaitmon::discrepancy_detail
