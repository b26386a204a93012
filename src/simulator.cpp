// The session simulator: gait timing, per-region contact trajectories, rasterisation, sensor model.
#include "gaitmon/simulator.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <numbers>
#include <random>
#include <span>
#include <stdexcept>
#include <utility>

#include "gaitmon/json.hpp"
#include "gaitmon/session.hpp"

namespace gaitmon {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr int kCoverageSubsamples = 8;  // per cell side
constexpr double kStandardGravity_m_per_s2 = 9.80665;
constexpr double kMinSwingFractionOfStride = 0.2;
constexpr double kJitterTruncationSd = 3.0;

/// Where each region is loaded within a stance, as fractions of the stance: its contact starts,
/// peaks and ends. Heel first, then midfoot, metatarsals and toes; met1_2 and toe1 leave last.
struct RegionWindow {
  double start;
  double peak;
  double end;
};
constexpr std::array<RegionWindow, kRegionCount> kWindows{{
    {0.00, 0.12, 0.52},  // heel
    {0.04, 0.32, 0.68},  // midfoot posterior
    {0.08, 0.45, 0.80},  // midfoot anterior
    {0.14, 0.82, 1.00},  // met1_2
    {0.10, 0.80, 0.99},  // met3_5
    {0.24, 0.88, 1.00},  // toe1
    {0.28, 0.86, 0.99},  // toe2
    {0.26, 0.85, 0.99},  // toes3_5
}};

/// A bump of height 1 on [start, end] peaking at `peak`: a rising half-cosine then a falling
/// one, so the value and its derivative are continuous everywhere (the derivative is 0 at the
/// ends and at the peak). Returns the value and d/du.
std::pair<double, double> bump(const RegionWindow& w, double u) {
  if (u <= w.start || u >= w.end) return {0.0, 0.0};
  if (u <= w.peak) {
    const double span = w.peak - w.start;
    const double phase = kPi * (u - w.start) / span;
    return {0.5 * (1.0 - std::cos(phase)), 0.5 * kPi / span * std::sin(phase)};
  }
  const double span = w.end - w.peak;
  const double phase = kPi * (u - w.peak) / span;
  return {0.5 * (1.0 + std::cos(phase)), -0.5 * kPi / span * std::sin(phase)};
}

/// Draws with a fully specified algorithm, so a seed gives the same numbers everywhere.
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : engine_(seed) {}

  /// In [0, 1): the top 53 bits of one draw.
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }

  /// Integer in [lo, hi].
  int uniform_int(int lo, int hi) {
    const auto count = static_cast<double>(hi - lo + 1);
    return lo + std::min(hi - lo, static_cast<int>(uniform() * count));
  }

  /// Standard normal by Box-Muller; the second value of each pair is kept for the next call.
  double normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    const double radius = std::sqrt(-2.0 * std::log(1.0 - uniform()));
    const double angle = 2.0 * kPi * uniform();
    spare_ = radius * std::sin(angle);
    has_spare_ = true;
    return radius * std::cos(angle);
  }

  double truncated_normal() {
    return std::clamp(normal(), -kJitterTruncationSd, kJitterTruncationSd);
  }

 private:
  std::mt19937_64 engine_;
  double spare_ = 0.0;
  bool has_spare_ = false;
};

/// A region's cells in the grid frame, gathered once per session.
struct RegionCells {
  std::vector<std::size_t> sensors;
  std::vector<double> x_mm;
  std::vector<double> y_mm;
  double centre_x_mm = 0.0;
  double centre_y_mm = 0.0;
  double width_mm = 0.0;
  double height_mm = 0.0;
  double box_width_mm = 0.0;  ///< the cells' bounding box, cell edges included
  double box_height_mm = 0.0;

  /// The position in `sensors` of the cell whose centre is nearest (x, y), the first on a tie.
  std::size_t nearest(double x, double y) const {
    std::size_t best = 0;
    double best_d2 = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < sensors.size(); ++i) {
      const double dx = x_mm[i] - x;
      const double dy = y_mm[i] - y;
      if (dx * dx + dy * dy < best_d2) {
        best_d2 = dx * dx + dy * dy;
        best = i;
      }
    }
    return best;
  }

  /// The area-preserving stretch of x (y shrinks by the same factor) that gives a contact
  /// ellipse of aspect A/B the aspect of the region's box, so it grows into the region's cells
  /// instead of spilling out of one side while the other stays empty. It keeps every area and
  /// the integral of the pressure, so force against contact area is the model's own.
  double stretch(const EllipsoidParams& params) const {
    return std::sqrt((box_width_mm / box_height_mm) / (params.A_mm / params.B_mm));
  }
  /// The largest ellipse of the box's aspect that stays inside it, as an area.
  double inscribed_area_mm2() const { return kPi / 4.0 * box_width_mm * box_height_mm; }
};

RegionCells gather_cells(const InsoleLayout& layout, Region region) {
  RegionCells cells;
  cells.width_mm = layout.geometry().width_mm;
  cells.height_mm = layout.geometry().height_mm;
  for (std::size_t index : layout.region_sensors(region)) {
    const Sensor& s = layout.sensor(index);
    cells.sensors.push_back(index);
    cells.x_mm.push_back(s.grid_x_mm);
    cells.y_mm.push_back(s.grid_y_mm);
  }
  const auto [x_lo, x_hi] = std::minmax_element(cells.x_mm.begin(), cells.x_mm.end());
  const auto [y_lo, y_hi] = std::minmax_element(cells.y_mm.begin(), cells.y_mm.end());
  cells.box_width_mm = *x_hi - *x_lo + cells.width_mm;
  cells.box_height_mm = *y_hi - *y_lo + cells.height_mm;
  cells.centre_x_mm = 0.5 * (*x_lo + *x_hi);
  cells.centre_y_mm = 0.5 * (*y_lo + *y_hi);
  return cells;
}

/// Writes one region's cell loads (N) into `out` (one per cell of `cells`).
void rasterise_into(const RegionCells& cells, const EllipsoidParams& params, double d_mm,
                    double ddot_mm_per_s, ModelVariant variant, Rasterisation mode, double force_n,
                    PlacementShift shift, std::span<double> out) {
  std::fill(out.begin(), out.end(), 0.0);
  if (!(force_n > 0.0) || !(d_mm > 0.0)) return;
  const PressureField field(params, d_mm, ddot_mm_per_s, variant);
  const double stretch = cells.stretch(params);
  const double rA = field.radii().rA_mm * stretch;
  const double rB = field.radii().rB_mm / stretch;
  const double w = cells.width_mm;
  const double h = cells.height_mm;
  const double centre_x = cells.centre_x_mm + shift.x_mm;
  const double centre_y = cells.centre_y_mm + shift.y_mm;
  const auto rho2_at = [&](double x, double y) {
    const double u = (x - centre_x) / rA;
    const double v = (y - centre_y) / rB;
    return u * u + v * v;
  };
  double total = 0.0;
  for (std::size_t i = 0; i < cells.sensors.size(); ++i) {
    // Cells wholly beyond the ellipse's bounding box carry nothing either way.
    if (std::abs(cells.x_mm[i] - centre_x) - 0.5 * w > rA ||
        std::abs(cells.y_mm[i] - centre_y) - 0.5 * h > rB) {
      continue;
    }
    double mean_pressure = 0.0;
    if (mode == Rasterisation::CellCentre) {
      mean_pressure = field.at_rho2(rho2_at(cells.x_mm[i], cells.y_mm[i]));
    } else {
      double sum = 0.0;
      for (int a = 0; a < kCoverageSubsamples; ++a) {
        const double x = cells.x_mm[i] + w * ((a + 0.5) / kCoverageSubsamples - 0.5);
        for (int b = 0; b < kCoverageSubsamples; ++b) {
          const double y = cells.y_mm[i] + h * ((b + 0.5) / kCoverageSubsamples - 0.5);
          sum += field.at_rho2(rho2_at(x, y));
        }
      }
      mean_pressure = sum / (kCoverageSubsamples * kCoverageSubsamples);
    }
    out[i] = std::max(0.0, mean_pressure) * w * h;
    total += out[i];
  }
  if (total > 0.0) {
    const double scale = force_n / total;
    for (double& load : out) load *= scale;
  } else {
    out[cells.nearest(centre_x, centre_y)] = force_n;
  }
}

void require(bool ok, const std::string& option, const std::string& reason) {
  if (!ok) throw std::invalid_argument("simulate: " + option + ": " + reason);
}

void validate(const SimulationOptions& o) {
  require(std::isfinite(o.duration_s) && o.duration_s > 0.0 && o.duration_s <= 86400.0,
          "duration_s", "must be in (0, 86400]");
  require(std::isfinite(o.body_mass_kg) && o.body_mass_kg > 0.0 && o.body_mass_kg <= 300.0,
          "body_mass_kg", "must be in (0, 300]");
  require(std::isfinite(o.timing.stride_s) && o.timing.stride_s > 0.5 && o.timing.stride_s <= 3.0,
          "stride_s", "must be in (0.5, 3]");
  require(o.timing.stance_fraction >= 0.3 && o.timing.stance_fraction <= 0.8, "stance_fraction",
          "must be in [0.3, 0.8]");
  require(o.timing.jitter_pct >= 0.0 && o.timing.jitter_pct <= 10.0, "jitter_pct",
          "must be in [0, 10]");
  require(o.noise_sd_bits >= 0.0 && o.noise_sd_bits <= 50.0, "noise_sd_bits", "must be in [0, 50]");
  require(o.max_bias_bits >= 0 && o.max_bias_bits <= 50, "max_bias_bits", "must be in [0, 50]");
  require(o.min_bias_bits >= 0 && o.min_bias_bits <= o.max_bias_bits, "min_bias_bits",
          "must be in [0, max_bias_bits]");
  require(o.tissue_step_sd_pct >= 0.0 && o.tissue_step_sd_pct <= 100.0, "tissue_step_sd_pct",
          "must be in [0, 100]");
  require(o.placement_sd_mm >= 0.0 && o.placement_sd_mm <= 10.0, "placement_sd_mm",
          "must be in [0, 10]");
  require(o.tissue_drift_pct_per_min >= -20.0 && o.tissue_drift_pct_per_min <= 20.0,
          "tissue_drift_pct_per_min", "must be in [-20, 20]");
  require(o.tissue_asymmetry_pct >= -50.0 && o.tissue_asymmetry_pct <= 50.0, "tissue_asymmetry_pct",
          "must be in [-50, 50]");
  for (Region r : kRegions) {
    const auto& p = o.region_params[index_of(r)];
    if (!p) continue;
    const std::string key = "region_params." + std::string(region_name(r));
    // The geometry is checked by the model; the material must make a loaded region push back.
    require(std::isfinite(p->kbar_n_per_mm3) && p->kbar_n_per_mm3 > 0.0, key, "kbar must be > 0");
    require(std::isfinite(p->cbar_ns_per_mm3) && p->cbar_ns_per_mm3 >= 0.0, key,
            "cbar must be >= 0");
    require(std::isfinite(p->n) && p->n > -1.0, key, "n must be > -1");
    require(std::isfinite(p->m) && p->m > -1.0, key, "m must be > -1");
  }
}

/// One stance of one foot in recording time.
struct Stance {
  double start_s = 0.0;
  double duration_s = 0.0;
  double end_s() const { return start_s + duration_s; }
};

/// Both feet's stances covering the recording, in time order per foot.
std::array<std::vector<Stance>, 2> plan_gait(const GaitTiming& timing, double duration_s,
                                             double start_phase_s, Rng& rng) {
  const double jitter = timing.jitter_pct / 100.0;
  // Gait time 0 is the first left heel strike, a stride and the start phase before the first
  // frame, so that every stance touching the recording is planned.
  const double lead_s = start_phase_s + timing.stride_s;
  std::vector<double> left_starts;
  std::vector<double> strides;
  for (double tau = 0.0; tau <= lead_s + duration_s + timing.stride_s;) {
    const double stride = timing.stride_s * (1.0 + jitter * rng.truncated_normal());
    left_starts.push_back(tau - lead_s);
    strides.push_back(stride);
    tau += stride;
  }
  std::array<std::vector<Stance>, 2> stances;
  for (std::size_t i = 0; i < left_starts.size(); ++i) {
    for (Foot foot : kFeet) {
      const double start = left_starts[i] + (foot == Foot::Right ? 0.5 * strides[i] : 0.0);
      const double stance =
          strides[i] * timing.stance_fraction * (1.0 + jitter * rng.truncated_normal());
      stances[static_cast<std::size_t>(foot)].push_back({start, stance});
    }
  }
  const double min_swing = kMinSwingFractionOfStride * timing.stride_s;
  for (auto& foot_stances : stances) {
    for (std::size_t i = 0; i + 1 < foot_stances.size(); ++i) {
      const double room = foot_stances[i + 1].start_s - foot_stances[i].start_s - min_swing;
      foot_stances[i].duration_s = std::min(foot_stances[i].duration_s, room);
    }
  }
  return stances;
}

/// The area stage: one region's contact at time t of a stance, or nothing out of its window.
struct RegionContact {
  double area_mm2 = 0.0;
  double d_mm = 0.0;
  double ddot_mm_per_s = 0.0;
};

std::optional<RegionContact> contact_at(const SimulatedRegion& simulated, Region region,
                                        const Stance& stance, double t_s) {
  const auto [area, rate_per_fraction] =
      planned_contact_area_mm2(simulated, region, (t_s - stance.start_s) / stance.duration_s);
  if (area <= 0.0) return std::nullopt;
  const double area_rate = rate_per_fraction / stance.duration_s;
  return RegionContact{area, deformation_mm(simulated.params, area),
                       deformation_rate_mm_per_s(simulated.params, area, area_rate)};
}

/// The last step of the sensor stage: round to bits and clip to the insole's 0..255.
std::uint8_t quantise(double reading_bits, SimulationTruth& truth) {
  const double rounded = std::floor(reading_bits + 0.5);
  if (rounded > 255.0) ++truth.clipped_high_samples;
  if (rounded < 0.0) ++truth.clipped_low_samples;
  return static_cast<std::uint8_t>(std::clamp(rounded, 0.0, 255.0));
}

/// What the truth records of one stance while the frames go by.
struct StanceTally {
  std::int64_t first_above = -1;
  std::int64_t last_above = -1;
  std::array<double, kRegionCount> peak_force_n{};
  double peak_total_force_n = 0.0;
  std::array<double, kRegionCount> kbar_factor{}, cbar_factor{};
  PlacementShift shift;
};

/// Every effect applied, in order, with every parameter (defaults filled in).
nlohmann::json effects_json(const SimulationOptions& o) {
  nlohmann::json effects = nlohmann::json::array();
  for (const std::string& name : o.effects) {
    const auto given = o.effect_params.find(name);
    const EffectParams params = resolve_effect_params(
        name, given == o.effect_params.end() ? EffectParams{} : given->second);
    effects.push_back({{"name", name}, {"params", params}});
  }
  return effects;
}

void write_truth(const SimulationTruth& truth, const std::filesystem::path& path) {
  const SimulationOptions& o = truth.options;
  nlohmann::json j;
  j["simulated"] = true;
  j["generator"] = "gaitmon simulate";
  j["model"] = std::string(model_variant_name(o.model));
  j["rasterisation"] = std::string(rasterisation_name(o.rasterisation));
  j["options"] = {{"insole_size", std::string(insole_size_name(o.size))},
                  {"duration_s", o.duration_s},
                  {"seed", o.seed},
                  {"body_mass_kg", o.body_mass_kg},
                  {"stride_s", o.timing.stride_s},
                  {"stance_fraction", o.timing.stance_fraction},
                  {"jitter_pct", o.timing.jitter_pct},
                  {"noise_sd_bits", o.noise_sd_bits},
                  {"min_bias_bits", o.min_bias_bits},
                  {"max_bias_bits", o.max_bias_bits},
                  {"tissue_step_sd_pct", o.tissue_step_sd_pct},
                  {"placement_sd_mm", o.placement_sd_mm},
                  {"tissue_drift_pct_per_min", o.tissue_drift_pct_per_min},
                  {"tissue_asymmetry_pct", o.tissue_asymmetry_pct},
                  {"effects", effects_json(o)},
                  {"subject", o.subject}};
  j["sample_rate_hz"] = truth.sample_rate_hz;
  j["frames_per_foot"] = truth.frames_per_foot;
  j["newtons_per_bit"] = truth.newtons_per_bit;
  j["event_threshold_n"] = truth.event_threshold_n;
  j["start_phase_s"] = truth.start_phase_s;
  j["negative_force_samples"] = truth.negative_force_samples;
  j["negative_force_policy"] = "region forces below 0 are set to 0";
  j["clipped_high_samples"] = truth.clipped_high_samples;
  j["clipped_low_samples"] = truth.clipped_low_samples;
  j["contact_area_cap_fraction_of_sensor_area"] = kMaxContactFractionOfSensorArea;
  j["contact_area_cap_fraction_of_inscribed_ellipse"] = kMaxContactFractionOfInscribedEllipse;
  nlohmann::json regions = nlohmann::json::object();
  for (Region r : kRegions) {
    const SimulatedRegion& sr = truth.regions[index_of(r)];
    nlohmann::json entry = nlohmann::json(sr.params);
    entry["sensor_area_mm2"] = sr.sensor_area_mm2;
    entry["peak_area_mm2"] = sr.peak_area_mm2;
    entry["target_elastic_force_n"] = sr.target_elastic_force_n;
    entry["peak_elastic_force_n"] = sr.peak_elastic_force_n;
    entry["area_capped"] = sr.area_capped;
    entry["peak_elastic_force_share"] = kPeakElasticForceShare[index_of(r)];
    const RegionWindow& w = kWindows[index_of(r)];
    entry["area_window_fraction_of_contact"] = {w.start, w.peak, w.end};
    regions[std::string(region_name(r))] = entry;
  }
  j["regions"] = regions;
  nlohmann::json biases = nlohmann::json::object();
  nlohmann::json steps = nlohmann::json::object();
  for (Foot foot : kFeet) {
    biases[std::string(foot_name(foot))] = truth.dc_bias_bits[static_cast<std::size_t>(foot)];
    steps[std::string(foot_name(foot))] = nlohmann::json::array();
  }
  for (const SimulatedStep& s : truth.steps) {
    nlohmann::json peaks = nlohmann::json::object();
    nlohmann::json factors = nlohmann::json::object();
    for (Region r : kRegions) {
      peaks[std::string(region_name(r))] = s.peak_force_n[index_of(r)];
      factors[std::string(region_name(r))] = {{"kbar", s.kbar_factor[index_of(r)]},
                                              {"cbar", s.cbar_factor[index_of(r)]}};
    }
    steps[std::string(foot_name(s.foot))].push_back({{"index", s.index},
                                                     {"t_heel_strike_s", s.t_heel_strike_s},
                                                     {"t_toe_off_s", s.t_toe_off_s},
                                                     {"heel_strike_frame", s.heel_strike_frame},
                                                     {"toe_off_frame", s.toe_off_frame},
                                                     {"partial", s.partial},
                                                     {"t_contact_start_s", s.t_contact_start_s},
                                                     {"t_contact_end_s", s.t_contact_end_s},
                                                     {"peak_total_force_n", s.peak_total_force_n},
                                                     {"peak_force_n", peaks}});
    // Only when the tissue varies: otherwise every factor is 1.
    if (o.tissue_step_sd_pct > 0.0 || o.tissue_drift_pct_per_min != 0.0 ||
        o.tissue_asymmetry_pct != 0.0) {
      steps[std::string(foot_name(s.foot))].back()["tissue_factors"] = factors;
    }
    if (o.placement_sd_mm > 0.0) {
      steps[std::string(foot_name(s.foot))].back()["placement_shift_mm"] = {
          {"x", s.placement_shift.x_mm}, {"y", s.placement_shift.y_mm}};
    }
  }
  j["dc_bias_bits"] = biases;
  j["steps"] = steps;
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << json_file_text(j);
  out.close();
  if (!out) throw std::runtime_error("cannot write the simulation truth " + path.string());
}

// The config's [sensor_creep] is the creep of the insoles it describes, which every reader
// undoes: simulated cells creep so too, unless the options give sensor_creep themselves. It goes
// where the effects' registry orders it (a sensor stage, before the effects on a whole frame).
SimulationOptions with_insoles_creep(const Config& config, SimulationOptions options) {
  constexpr std::string_view kCreep = "sensor_creep";
  if (config.sensor_creep.gain == 0.0 ||
      std::ranges::find(options.effects, kCreep) != options.effects.end()) {
    return options;
  }
  const std::vector<std::string_view> order = simulation_effect_names();
  const auto rank = [&](std::string_view name) { return std::ranges::find(order, name); };
  const auto after = std::ranges::find_if(
      options.effects, [&](const std::string& name) { return rank(name) > rank(kCreep); });
  options.effects.insert(after, std::string(kCreep));
  options.effect_params[std::string(kCreep)] = {{"gain", config.sensor_creep.gain},
                                                {"tau_s", config.sensor_creep.tau_s}};
  return options;
}

}  // namespace

std::string_view rasterisation_name(Rasterisation mode) {
  return mode == Rasterisation::CellCentre ? "centre" : "coverage";
}

std::optional<Rasterisation> parse_rasterisation(std::string_view text) {
  if (text == "centre") return Rasterisation::CellCentre;
  if (text == "coverage") return Rasterisation::Coverage;
  return std::nullopt;
}

std::pair<double, double> planned_contact_area_mm2(const SimulatedRegion& simulated, Region region,
                                                   double fraction) {
  const auto [shape, shape_rate] = bump(kWindows[index_of(region)], fraction);
  return {simulated.peak_area_mm2 * shape, simulated.peak_area_mm2 * shape_rate};
}

double contact_area_for_elastic_force(const EllipsoidParams& params, double target_force_n,
                                      double max_area_mm2) {
  const auto elastic = [&](double area) {
    return force_n(params, deformation_mm(params, area), 0.0, ModelVariant::Correct);
  };
  if (!(target_force_n > 0.0)) return 0.0;
  if (elastic(max_area_mm2) <= target_force_n) return max_area_mm2;
  // The elastic force grows monotonically with the area, so bisection converges.
  double lo = 0.0;
  double hi = max_area_mm2;
  for (int i = 0; i < 200 && hi - lo > 1e-12 * max_area_mm2; ++i) {
    const double mid = 0.5 * (lo + hi);
    (elastic(mid) < target_force_n ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

std::vector<double> rasterise_region(const InsoleLayout& layout, Region region,
                                     const EllipsoidParams& params, double d_mm,
                                     double ddot_mm_per_s, ModelVariant variant, Rasterisation mode,
                                     double force_n, PlacementShift shift) {
  const RegionCells cells = gather_cells(layout, region);
  std::vector<double> loads(cells.sensors.size());
  rasterise_into(cells, params, d_mm, ddot_mm_per_s, variant, mode, force_n, shift, loads);
  return loads;
}

SimulationTruth simulate_session(const Config& config, const SimulationOptions& requested,
                                 const std::filesystem::path& csv_out,
                                 const std::filesystem::path& truth_json_out) {
  validate(requested);
  const SimulationOptions options = with_insoles_creep(config, requested);
  std::vector<std::unique_ptr<SimulationEffect>> effects;
  for (const std::string& name : options.effects) {
    const auto params = options.effect_params.find(name);
    if (auto effect = make_simulation_effect(
            name, params == options.effect_params.end() ? EffectParams{} : params->second)) {
      effects.push_back(std::move(effect));
    }
  }
  const InsoleLayout layout(config.insole(options.size), config.sensor);
  const std::size_t sensor_count = layout.sensor_count();

  SimulationTruth truth;
  truth.options = options;
  truth.sample_rate_hz = config.sample_rate_hz;
  truth.frames_per_foot = std::llround(options.duration_s * config.sample_rate_hz);
  require(truth.frames_per_foot >= 1, "duration_s", "shorter than one frame");
  truth.newtons_per_bit = config.calibration.newtons_per_bit(config.sensor.area_mm2());
  truth.event_threshold_n = config.segmentation.event_threshold_bits * truth.newtons_per_bit;

  const double body_weight_n = options.body_mass_kg * kStandardGravity_m_per_s2;
  std::array<RegionCells, kRegionCount> cells;
  for (Region r : kRegions) {
    const std::size_t ri = index_of(r);
    SimulatedRegion& sr = truth.regions[ri];
    sr.params = options.region_params[ri].value_or(config.tissue(options.size, r).mean);
    const IdentifiableParams id = identifiable(sr.params);  // validates the geometry
    cells[ri] = gather_cells(layout, r);
    sr.sensor_area_mm2 = static_cast<double>(cells[ri].sensors.size()) * config.sensor.area_mm2();
    const double max_area = std::min(
        {kMaxContactFractionOfSensorArea * sr.sensor_area_mm2,
         kMaxContactFractionOfInscribedEllipse * cells[ri].inscribed_area_mm2(), 0.99 * id.P_mm2});
    sr.target_elastic_force_n = kPeakElasticForceShare[ri] * body_weight_n;
    sr.peak_area_mm2 =
        contact_area_for_elastic_force(sr.params, sr.target_elastic_force_n, max_area);
    sr.area_capped = sr.peak_area_mm2 == max_area;
    sr.peak_elastic_force_n =
        force_n(sr.params, deformation_mm(sr.params, sr.peak_area_mm2), 0.0, ModelVariant::Correct);
  }

  Rng rng(options.seed);
  truth.start_phase_s = rng.uniform() * options.timing.stride_s;
  const auto stances = plan_gait(options.timing, options.duration_s, truth.start_phase_s, rng);
  for (Foot foot : kFeet) {
    auto& bias = truth.dc_bias_bits[static_cast<std::size_t>(foot)];
    bias.resize(sensor_count);
    for (int& b : bias) b = rng.uniform_int(options.min_bias_bits, options.max_bias_bits);
  }

  std::array<std::vector<StanceTally>, 2> tallies{std::vector<StanceTally>(stances[0].size()),
                                                  std::vector<StanceTally>(stances[1].size())};
  // Drawn only when asked for, so that sessions without variation keep their bytes.
  const double step_sd = options.tissue_step_sd_pct / 100.0;
  const double drift_per_min = 1.0 + options.tissue_drift_pct_per_min / 100.0;
  for (std::size_t fi = 0; fi < tallies.size(); ++fi) {
    const double foot_factor =
        kFeet[fi] == Foot::Right ? 1.0 + options.tissue_asymmetry_pct / 100.0 : 1.0;
    for (std::size_t c = 0; c < tallies[fi].size(); ++c) {
      StanceTally& tally = tallies[fi][c];
      const double steady = foot_factor * std::pow(drift_per_min, stances[fi][c].start_s / 60.0);
      for (Region r : kRegions) {
        const std::size_t ri = index_of(r);
        tally.kbar_factor[ri] = steady * (step_sd > 0.0 ? std::exp(step_sd * rng.normal()) : 1.0);
        tally.cbar_factor[ri] = steady * (step_sd > 0.0 ? std::exp(step_sd * rng.normal()) : 1.0);
      }
    }
  }
  if (options.placement_sd_mm > 0.0) {
    for (auto& foot_tallies : tallies) {
      for (StanceTally& tally : foot_tallies) {
        tally.shift.x_mm = options.placement_sd_mm * rng.normal();
        tally.shift.y_mm = options.placement_sd_mm * rng.normal();
      }
    }
  }

  SessionHeader header;
  header.insole_size = options.size;
  header.sample_rate_hz = config.sample_rate_hz;
  header.sensors = sensor_count;
  header.subject = options.subject;
  header.body_mass_kg = options.body_mass_kg;
  header.note = "SIMULATED by gaitmon simulate (seed " + std::to_string(options.seed) + ", model " +
                std::string(model_variant_name(options.model)) + ")";
  SessionWriter writer(csv_out, header);

  const double t_last_s = static_cast<double>(truth.frames_per_foot - 1) / config.sample_rate_hz;
  std::array<std::size_t, 2> cursor{0, 0};
  std::vector<double> cell_n(sensor_count);
  std::vector<double> readings(sensor_count);
  std::vector<double> region_n;
  Frame frame;
  frame.bits.resize(sensor_count);

  for (std::int64_t k = 0; k < truth.frames_per_foot; ++k) {
    const double t = static_cast<double>(k) / config.sample_rate_hz;
    for (Foot foot : kFeet) {
      const auto fi = static_cast<std::size_t>(foot);
      std::fill(cell_n.begin(), cell_n.end(), 0.0);
      const auto& foot_stances = stances[fi];
      std::size_t& c = cursor[fi];
      while (c < foot_stances.size() && foot_stances[c].end_s() < t) ++c;
      if (c < foot_stances.size() && foot_stances[c].start_s <= t) {
        const Stance& stance = foot_stances[c];
        StanceTally& tally = tallies[fi][c];
        double total_n = 0.0;
        for (Region r : kRegions) {
          const std::size_t ri = index_of(r);
          const SimulatedRegion& sr = truth.regions[ri];
          const auto contact = contact_at(sr, r, stance, t);
          if (!contact) continue;
          EllipsoidParams params = sr.params;
          params.kbar_n_per_mm3 *= tally.kbar_factor[ri];
          params.cbar_ns_per_mm3 *= tally.cbar_factor[ri];
          double force = force_n(params, contact->d_mm, contact->ddot_mm_per_s, options.model);
          const TissueSample sample{foot,
                                    r,
                                    t,
                                    stance.start_s,
                                    contact->area_mm2,
                                    contact->d_mm,
                                    contact->ddot_mm_per_s,
                                    1.0 / config.sample_rate_hz};
          for (auto& effect : effects) force = effect->tissue_force_n(sample, force);
          if (force < 0.0) {
            ++truth.negative_force_samples;
            force = 0.0;
          }
          region_n.resize(cells[ri].sensors.size());
          rasterise_into(cells[ri], params, contact->d_mm, contact->ddot_mm_per_s, options.model,
                         options.rasterisation, force, tally.shift, region_n);
          for (std::size_t i = 0; i < region_n.size(); ++i) {
            cell_n[cells[ri].sensors[i]] = region_n[i];
          }
          total_n += force;
          tally.peak_force_n[ri] = std::max(tally.peak_force_n[ri], force);
        }
        tally.peak_total_force_n = std::max(tally.peak_total_force_n, total_n);
        if (total_n > truth.event_threshold_n) {
          if (tally.first_above < 0) tally.first_above = k;
          tally.last_above = k;
        }
      }

      const auto& bias = truth.dc_bias_bits[fi];
      for (std::size_t s = 0; s < sensor_count; ++s) {
        double& reading = readings[s];
        reading = cell_n[s] / truth.newtons_per_bit;
        const SensorSample sample{foot, s, t};
        for (auto& effect : effects) reading = effect->sensor_bits(sample, reading);
      }
      for (auto& effect : effects) effect->sensor_frame(layout, readings);
      for (std::size_t s = 0; s < sensor_count; ++s) {
        double reading = readings[s] + bias[s];
        if (options.noise_sd_bits > 0.0) reading += options.noise_sd_bits * rng.normal();
        frame.bits[s] = quantise(reading, truth);
      }
      frame.t_s = t;
      frame.foot = foot;
      writer.write(frame);
    }
  }
  writer.close();

  for (Foot foot : kFeet) {
    const auto fi = static_cast<std::size_t>(foot);
    int index = 0;
    for (std::size_t i = 0; i < stances[fi].size(); ++i) {
      const StanceTally& tally = tallies[fi][i];
      if (tally.first_above < 0) continue;
      SimulatedStep step;
      step.foot = foot;
      step.index = index++;
      step.heel_strike_frame = tally.first_above;
      step.toe_off_frame = tally.last_above;
      step.t_heel_strike_s = static_cast<double>(tally.first_above) / config.sample_rate_hz;
      step.t_toe_off_s = static_cast<double>(tally.last_above) / config.sample_rate_hz;
      step.t_contact_start_s = stances[fi][i].start_s;
      step.t_contact_end_s = stances[fi][i].end_s();
      step.partial = step.t_contact_start_s < 0.0 || step.t_contact_end_s > t_last_s;
      step.peak_force_n = tally.peak_force_n;
      step.peak_total_force_n = tally.peak_total_force_n;
      step.kbar_factor = tally.kbar_factor;
      step.cbar_factor = tally.cbar_factor;
      step.placement_shift = tally.shift;
      truth.steps.push_back(step);
    }
  }
  std::stable_sort(truth.steps.begin(), truth.steps.end(),
                   [](const SimulatedStep& a, const SimulatedStep& b) {
                     return a.t_heel_strike_s < b.t_heel_strike_s;
                   });
  write_truth(truth, truth_json_out);
  return truth;
}

}  // namespace gaitmon
