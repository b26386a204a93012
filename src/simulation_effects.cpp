// Physical effects the simulator can add on top of the ellipsoid model, so that sessions with a
// hidden effect can be made for the discrepancy workflow (issue 5).
//
// Tissue stage (the region's force F from the model, before rasterisation):
// - stress_relaxation: a Maxwell branch in quasi-linear viscoelastic form. With the reduced
//   relaxation function G(t) = 1 - g + g exp(-t / tau), F_out = F - g r, where r is F low-passed
//   with time constant tau (r' = (F - r) / tau, per foot and region, decaying through the swing).
//   Under a held load the force relaxes to (1 - g) F. strength g in [0.05, 0.6], tau_s in
//   [0.02, 2] s: QLV fits of the heel pad and plantar soft tissue report fast time constants of
//   tens to hundreds of ms and 20-60 % relaxation.
// - hysteresis: rate-independent loading/unloading asymmetry, F_out = F (1 + h z). z is a Dahl
//   state driven by the deformation alone: dz/dd = (sign(dd) - z) / d_s, so z tends to +1 while
//   the tissue is being compressed and to -1 while it recovers, switching over transition_mm of
//   deformation whatever the speed. strength h in [0.03, 0.3] (loading exceeds unloading by 2 h
//   at the same deformation: 6-60 %, within the heel pad's reported 30-60 % energy loss),
//   transition_mm in [0.05, 2].
// - impact_transient: a heel-strike transient on the heel region only, a half-sine pulse
//   F_out = F + a sin(pi tau / T) for tau = t - contact start in [0, T]. amplitude_n in
//   [20, 200] N (about 0.03-0.35 body weights at 60 kg), duration_s in [0.02, 0.08] s.
//
// Sensor stage (one cell's reading in bits, before dc bias, noise, rounding and clipping):
// - sensor_saturation: the cell stops rising at a ceiling, bits_out = min(bits, ceiling_bits);
//   ceiling_bits in [60, 250] (the ADC's own 255 clip applies anyway).
// - sensor_creep: the reading drifts upward under sustained load, bits_out = bits + beta r with r
//   the cell's bits low-passed with time constant tau (decaying in the swing), so a held load
//   reads (1 + beta) of its value after a few tau. gain beta in [0.02, 0.4], tau_s in [0.2, 10] s
//   (capacitive insoles creep by a few per cent, resistive ones by up to 20-30 %, over seconds).
// - thermal_drift: the insole warms from room temperature toward the foot's from the start of
//   the recording, and every cell's unloaded reading moves with it: bits_out = bits + o (1 -
//   exp(-t / tau)), loaded or not (a warmer resistive cell conducts more). offset_bits in
//   [0.5, 20] (the rise still to come at t = 0, up to 8 % of the range), tau_s in [30, 1800] s
//   (a thin insole in a shoe reaches skin temperature over minutes). Assumed sizes: no thermal
//   specification of the Medilogic cells was at hand.
//
// Frame stage (one foot's whole frame of readings, after the sensor stage):
// - crosstalk: part of each cell's signal shows in the cells next to it (the row and column lines
//   a scanned resistive matrix shares, and a cover that spreads the load past a cell's edge):
//   bits_out_i = bits_i + k sum_j e_ij bits_j over the cells j that share an edge with i, e_ij
//   the share of the edge (InsoleLayout::neighbours). coupling k in [0.01, 0.15] per whole edge:
//   unisolated resistive arrays are reported to couple a few to over ten per cent into their
//   neighbours. Assumed sizes, as thermal_drift's.
//
// The filters use the exact step response of a first-order lag between successive samples, with
// the newer input held over the interval. That is exact for an input that steps at the samples;
// for a smoothly changing one it leads by half a sample, as a lag shorter by that much would (5 ms
// at 100 Hz, against time constants of 20 ms to 10 s; the discrepancy workflow's candidates use
// the same update, so its fitted tau carries the same half sample).
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "gaitmon/simulator.hpp"

namespace gaitmon {
namespace {

constexpr double kPi = std::numbers::pi;

/// A first-order lag per key, advanced to each sample's time with the sample's input.
class Lag {
 public:
  explicit Lag(double tau_s) : tau_s_(tau_s) {}

  double step(std::size_t key, double t_s, double input) {
    if (key >= state_.size()) state_.resize(key + 1);
    State& s = state_[key];
    if (!s.started) s = {true, t_s, 0.0};
    const double keep = std::exp(-(t_s - s.t_s) / tau_s_);
    s.value = s.value * keep + input * (1.0 - keep);
    s.t_s = t_s;
    return s.value;
  }

  /// As step, for an input seen only while it is nonzero: frames not seen since the last one
  /// (and before the first) are unloaded, so the lag decays without input to the frame before.
  double step_after_rest(std::size_t key, double t_s, double frame_interval_s, double input) {
    if (key >= state_.size()) state_.resize(key + 1);
    State& s = state_[key];
    const double rest_until_s = t_s - frame_interval_s;
    if (!s.started) {
      s = {true, rest_until_s, 0.0};
    } else if (s.t_s < rest_until_s) {
      s.value *= std::exp(-(rest_until_s - s.t_s) / tau_s_);
      s.t_s = rest_until_s;
    }
    return step(key, t_s, input);
  }

 private:
  struct State {
    bool started = false;
    double t_s = 0.0;
    double value = 0.0;
  };
  double tau_s_;
  std::vector<State> state_;
};

std::size_t tissue_key(const TissueSample& s) {
  return static_cast<std::size_t>(s.foot) * kRegionCount + index_of(s.region);
}

class StressRelaxation final : public SimulationEffect {
 public:
  explicit StressRelaxation(const EffectParams& p) : g_(p.at("strength")), lag_(p.at("tau_s")) {}
  double tissue_force_n(const TissueSample& s, double force_n) override {
    return force_n - g_ * lag_.step_after_rest(tissue_key(s), s.t_s, s.frame_interval_s, force_n);
  }

 private:
  double g_;
  Lag lag_;
};

class Hysteresis final : public SimulationEffect {
 public:
  explicit Hysteresis(const EffectParams& p)
      : h_(p.at("strength")), transition_mm_(p.at("transition_mm")) {}
  double tissue_force_n(const TissueSample& s, double force_n) override {
    const std::size_t key = tissue_key(s);
    if (key >= state_.size()) state_.resize(key + 1);
    State& st = state_[key];
    if (st.contact_start_s != s.t_contact_start_s) {
      // This is called in contact only: the swing before a contact, unsampled, unloads the
      // tissue to d = 0.
      st.z = -1.0 + (st.z + 1.0) * std::exp(-std::max(st.d_mm, 0.0) / transition_mm_);
      st.d_mm = 0.0;
      st.contact_start_s = s.t_contact_start_s;
    }
    const double step_mm = s.d_mm - st.d_mm;
    if (step_mm != 0.0) {
      // The exact solution of dz/dd = (sign - z) / d_s over a monotone step.
      const double target = step_mm > 0.0 ? 1.0 : -1.0;
      st.z = target + (st.z - target) * std::exp(-std::abs(step_mm) / transition_mm_);
      st.d_mm = s.d_mm;
    }
    return force_n * (1.0 + h_ * st.z);
  }

 private:
  struct State {
    double d_mm = 0.0;
    double z = -1.0;  ///< unloaded tissue has recovered
    double contact_start_s = std::numeric_limits<double>::quiet_NaN();
  };
  double h_;
  double transition_mm_;
  std::vector<State> state_;
};

class ImpactTransient final : public SimulationEffect {
 public:
  explicit ImpactTransient(const EffectParams& p)
      : amplitude_n_(p.at("amplitude_n")), duration_s_(p.at("duration_s")) {}
  double tissue_force_n(const TissueSample& s, double force_n) override {
    if (s.region != Region::Heel) return force_n;
    const double tau = s.t_s - s.t_contact_start_s;
    if (tau <= 0.0 || tau >= duration_s_) return force_n;
    return force_n + amplitude_n_ * std::sin(kPi * tau / duration_s_);
  }

 private:
  double amplitude_n_;
  double duration_s_;
};

class SensorSaturation final : public SimulationEffect {
 public:
  explicit SensorSaturation(const EffectParams& p) : ceiling_bits_(p.at("ceiling_bits")) {}
  double sensor_bits(const SensorSample& /*sample*/, double bits) override {
    return std::min(bits, ceiling_bits_);
  }

 private:
  double ceiling_bits_;
};

class SensorCreep final : public SimulationEffect {
 public:
  explicit SensorCreep(const EffectParams& p) : beta_(p.at("gain")), lag_(p.at("tau_s")) {}
  double sensor_bits(const SensorSample& s, double bits) override {
    // Sensors are numbered from 0 per foot; the right foot's follow the left's.
    const std::size_t key = s.sensor * 2 + static_cast<std::size_t>(s.foot);
    return bits + beta_ * lag_.step(key, s.t_s, bits);
  }

 private:
  double beta_;
  Lag lag_;
};

class ThermalDrift final : public SimulationEffect {
 public:
  explicit ThermalDrift(const EffectParams& p)
      : offset_bits_(p.at("offset_bits")), tau_s_(p.at("tau_s")) {}
  double sensor_bits(const SensorSample& s, double bits) override {
    return bits + offset_bits_ * -std::expm1(-s.t_s / tau_s_);
  }

 private:
  double offset_bits_;
  double tau_s_;
};

class Crosstalk final : public SimulationEffect {
 public:
  explicit Crosstalk(const EffectParams& p) : coupling_(p.at("coupling")) {}
  void sensor_frame(const InsoleLayout& layout, std::span<double> bits) override {
    own_.assign(bits.begin(), bits.end());
    for (std::size_t s = 0; s < bits.size(); ++s) {
      for (const Neighbour& n : layout.neighbours(s)) {
        bits[s] += coupling_ * n.shared_edge * own_[n.sensor];
      }
    }
  }

 private:
  double coupling_;
  std::vector<double> own_;
};

struct EffectEntry {
  std::string_view name;
  std::vector<EffectParamSpec> params;
  std::unique_ptr<SimulationEffect> (*make)(const EffectParams&);
};

template <class E>
std::unique_ptr<SimulationEffect> make(const EffectParams& p) {
  return std::make_unique<E>(p);
}

const std::vector<EffectEntry>& registry() {
  static const std::vector<EffectEntry> entries{
      {"none",
       {},
       [](const EffectParams&) -> std::unique_ptr<SimulationEffect> { return nullptr; }},
      {"stress_relaxation",
       {{"strength", 0.3, 0.05, 0.6, "fraction of the force that relaxes under a held load"},
        {"tau_s", 0.15, 0.02, 2.0, "relaxation time constant, s"}},
       make<StressRelaxation>},
      {"hysteresis",
       {{"strength", 0.12, 0.03, 0.3, "force gain while loading, loss while unloading"},
        {"transition_mm", 0.3, 0.05, 2.0, "deformation over which loading turns to unloading"}},
       make<Hysteresis>},
      {"impact_transient",
       {{"amplitude_n", 80.0, 20.0, 200.0, "peak of the heel-strike pulse, N"},
        {"duration_s", 0.04, 0.02, 0.08, "length of the half-sine pulse, s"}},
       make<ImpactTransient>},
      {"sensor_saturation",
       {{"ceiling_bits", 150.0, 60.0, 250.0, "reading at which a cell stops rising, bits"}},
       make<SensorSaturation>},
      {"sensor_creep",
       {{"gain", 0.15, 0.0, 2.0, "extra reading under a held load, fraction"},
        {"tau_s", 1.5, 0.02, 60.0, "creep time constant, s"}},
       make<SensorCreep>},
      {"thermal_drift",
       {{"offset_bits", 5.0, 0.5, 20.0, "rise of every cell's unloaded reading, bits"},
        {"tau_s", 300.0, 30.0, 1800.0, "warm-up time constant, s"}},
       make<ThermalDrift>},
      {"crosstalk",
       {{"coupling", 0.05, 0.01, 0.15,
         "share of a cell's reading that a neighbour across a whole edge also reads"}},
       make<Crosstalk>},
  };
  return entries;
}

const EffectEntry& entry_for(std::string_view name) {
  std::string known;
  for (const EffectEntry& e : registry()) {
    if (e.name == name) return e;
    known += (known.empty() ? "" : ", ") + std::string(e.name);
  }
  throw std::invalid_argument("unknown simulation effect '" + std::string(name) +
                              "' (known: " + known + ")");
}

}  // namespace

std::vector<std::string_view> simulation_effect_names() {
  std::vector<std::string_view> names;
  for (const EffectEntry& e : registry()) names.push_back(e.name);
  return names;
}

std::vector<EffectParamSpec> simulation_effect_params(std::string_view name) {
  return entry_for(name).params;
}

EffectParams resolve_effect_params(std::string_view name, const EffectParams& params) {
  const EffectEntry& e = entry_for(name);
  EffectParams out;
  std::string known;
  for (const EffectParamSpec& spec : e.params) {
    known += (known.empty() ? "" : ", ") + std::string(spec.name);
    out[std::string(spec.name)] = spec.default_value;
  }
  for (const auto& [key, value] : params) {
    const auto it = out.find(key);
    if (it == out.end()) {
      throw std::invalid_argument("effect '" + std::string(name) + "': unknown parameter '" + key +
                                  "' (known: " + (known.empty() ? "none" : known) + ")");
    }
    for (const EffectParamSpec& spec : e.params) {
      if (spec.name != key) continue;
      if (!std::isfinite(value) || value < spec.min || value > spec.max) {
        throw std::invalid_argument("effect '" + std::string(name) + "': parameter '" + key +
                                    "' = " + std::to_string(value) + " is outside [" +
                                    std::to_string(spec.min) + ", " + std::to_string(spec.max) +
                                    "] (" + std::string(spec.meaning) + ")");
      }
    }
    it->second = value;
  }
  return out;
}

std::unique_ptr<SimulationEffect> make_simulation_effect(std::string_view name,
                                                         const EffectParams& params) {
  return entry_for(name).make(resolve_effect_params(name, params));
}

}  // namespace gaitmon
