// The chain's shared error measured on simulated sessions: simulate, analyse as `analyze` does at
// each step's own m and at one m per session, collect the pooled means' errors, solve for the SDs.
#include "gaitmon/calibration.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "gaitmon/analysis.hpp"
#include "gaitmon/batch.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/simulator.hpp"
#include "parallel_for.hpp"
#include "toml_reader.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;

// The largest SD looked for: 1000 % in kbar and cbar, the most [pooling] takes.
constexpr double kLargestSd = 10.0;

MaterialVector scaled_truth(const SimulationTruth& truth, std::size_t region) {
  const EllipsoidParams& t = truth.regions[region].params;
  return {std::log(t.kbar_n_per_mm3), t.n, std::log(t.cbar_ns_per_mm3), t.m};
}

// Each step's own estimates, as with_chain_error takes them before the chain's SDs.
void add_steps(std::span<const StepAnalysis> steps, const SimulationTruth& truth,
               const MaterialBounds& bounds, ChainSamples& out) {
  for (const StepAnalysis& step : steps) {
    for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
      std::optional<MaterialEstimate> e = material_estimate(step.regions[ri].fit);
      if (!e) continue;
      *e = within_m_range(*e, bounds);
      const MaterialVector t = scaled_truth(truth, ri);
      const double m_variance = e->covariance[3][3];
      for (std::size_t p = 0; p < 4; ++p) {
        const double slope = e->slope_on_shared_m && p < 3 ? (*e->slope_on_shared_m)[p] : 0.0;
        out.steps[ri][p].push_back({e->value[p] - t[p],
                                    std::sqrt(e->covariance[p][p] + slope * slope * m_variance),
                                    slope});
      }
    }
  }
}

void add_session(const SessionAnalysis& session, const SimulationTruth& truth, ChainSamples& out) {
  for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
    const RegionSessionAnalysis& region = session.regions[ri];
    if (region.pooling.pooled) {
      const MaterialVector truth_scaled = scaled_truth(truth, ri);
      for (std::size_t p = 0; p < 4; ++p) {
        const double slope = region.pooling.mean_slope_on_shared_m
                                 ? (*region.pooling.mean_slope_on_shared_m)[p]
                                 : 0.0;
        // m's own chain SD is what the others' take through their slopes, not m's slope on itself.
        out.pooled[ri][p].push_back({region.pooling.mean[p] - truth_scaled[p],
                                     std::sqrt(region.pooling.mean_covariance[p][p]),
                                     p == 3 ? 0.0 : slope});
      }
    }
    const std::array<const std::optional<FootAsymmetry>*, 2> feet = {&region.kbar_asymmetry,
                                                                     &region.cbar_asymmetry};
    for (std::size_t p = 0; p < 2; ++p) {
      if (*feet[p])
        out.feet[ri][p].push_back({(*feet[p])->ln_ratio, (*feet[p])->se_steps_ln_ratio});
    }
  }
}

void append(const ChainSamples& from, ChainSamples& to) {
  for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
    for (std::size_t p = 0; p < 4; ++p) {
      to.pooled[ri][p].insert(to.pooled[ri][p].end(), from.pooled[ri][p].begin(),
                              from.pooled[ri][p].end());
      to.steps[ri][p].insert(to.steps[ri][p].end(), from.steps[ri][p].begin(),
                             from.steps[ri][p].end());
    }
    for (std::size_t p = 0; p < 2; ++p) {
      to.feet[ri][p].insert(to.feet[ri][p].end(), from.feet[ri][p].begin(), from.feet[ri][p].end());
    }
  }
}

// The analyses in the order `analyze` hands them to analyse_session: by foot, then step.
SessionAnalysis analyse_in_order(std::vector<StepAnalysis> steps, const Config& config,
                                 InsoleSize size) {
  std::sort(steps.begin(), steps.end(), [](const StepAnalysis& a, const StepAnalysis& b) {
    return std::pair(a.foot, a.step) < std::pair(b.foot, b.step);
  });
  return analyse_session(steps, config, size, {});
}

// One session's samples, both ways of fitting m: at most one per region and parameter, so that
// a design of any size keeps only numbers, not its analyses.
struct SessionSamples {
  ChainSamples per_step;
  ChainSamples m_per_session;
};

SessionSamples run_session(const Config& config, const CalibrationDesign& design, std::size_t i,
                           const fs::path& dir, ContactEllipseCache& cache) {
  SimulationOptions options;
  options.size = design.size_of(i);
  options.seed = design.seed_of(i);
  options.duration_s = design.duration_s;
  options.body_mass_kg = design.body_mass_kg_of(i);
  options.noise_sd_bits = design.noise_sd_bits;
  options.max_bias_bits = design.max_bias_bits;
  options.placement_sd_mm = design.placement_sd_mm;
  options.rasterisation = design.rasterisation;
  AnalysisSettings settings;
  if (design.rasterisation == Rasterisation::Coverage) settings.area = AreaSource::FootprintMean;
  const fs::path csv = dir / fmt::format("session-{}.csv", i);
  const fs::path truth_json = dir / fmt::format("session-{}.truth.json", i);
  const SimulationTruth truth = simulate_session(config, options, csv, truth_json);
  const InsoleLayout layout(config.insole(options.size), config.sensor);
  std::vector<StepAnalysis> steps;
  segment_session(csv, config, [&](Step&& step) {
    if (step.status == StepStatus::Ok)
      steps.push_back(analyse_step(step, layout, config, settings, &cache));
  });
  fs::remove(csv);
  fs::remove(truth_json);
  std::vector<StepAnalysis> at_shared_m = steps;
  fit_damping_exponent_per_session(at_shared_m, config, settings);
  SessionSamples samples;
  const MaterialBounds bounds = material_bounds(config.fit_bounds);
  add_steps(steps, truth, bounds, samples.per_step);
  add_steps(at_shared_m, truth, bounds, samples.m_per_session);
  add_session(analyse_in_order(std::move(steps), config, options.size), truth, samples.per_step);
  add_session(analyse_in_order(std::move(at_shared_m), config, options.size), truth,
              samples.m_per_session);
  return samples;
}

}  // namespace

std::size_t CalibrationDesign::session_count() const {
  return sizes.size() * static_cast<std::size_t>(last_seed - first_seed + 1);
}

InsoleSize CalibrationDesign::size_of(std::size_t session) const {
  return sizes.at(session / static_cast<std::size_t>(last_seed - first_seed + 1));
}

std::uint64_t CalibrationDesign::seed_of(std::size_t session) const {
  return first_seed + session % static_cast<std::size_t>(last_seed - first_seed + 1);
}

double CalibrationDesign::body_mass_kg_of(std::size_t session) const {
  if (last_seed == first_seed) return min_body_mass_kg;
  const double share = static_cast<double>(seed_of(session) - first_seed) /
                       static_cast<double>(last_seed - first_seed);
  return std::round(10.0 * (min_body_mass_kg + (max_body_mass_kg - min_body_mass_kg) * share)) /
         10.0;
}

void CalibrationDesign::check() const {
  const auto fail = [](const std::string& what) {
    throw std::invalid_argument("calibration design: " + what);
  };
  if (sizes.empty()) fail("sizes: none given");
  if (first_seed > last_seed) {
    fail(fmt::format("seeds: the first ({}) is after the last ({})", first_seed, last_seed));
  }
  if (last_seed - first_seed >= 100000) fail("seeds: more than 100000");
  if (!(duration_s > 0.0 && duration_s <= 86400.0)) {
    fail(fmt::format("duration_s must be in (0, 86400], got {}", duration_s));
  }
  if (!(min_body_mass_kg > 0.0 && min_body_mass_kg <= max_body_mass_kg &&
        max_body_mass_kg <= 300.0)) {
    fail(fmt::format("body mass must be 0 < min <= max <= 300 kg, got {} to {}", min_body_mass_kg,
                     max_body_mass_kg));
  }
}

namespace {

// `key` = [first, last] of two numbers within [low, high], first <= last.
std::pair<double, double> read_range(detail::TableReader& table, std::string_view key, double low,
                                     double high) {
  const toml::array& range = table.array(key);
  if (range.size() != 2) {
    table.fail(key, fmt::format("expected [first, last], got {} value(s)", range.size()));
  }
  std::array<double, 2> values{};
  for (std::size_t i = 0; i < 2; ++i) {
    const toml::node& element = *range.get(i);
    const std::optional<double> value = element.value<double>();
    if (!value || !std::isfinite(*value) || *value < low || *value > high) {
      detail::fail_element(table.file(), table.key_path(key), element,
                           fmt::format("expected a number in [{}, {}]", low, high));
    }
    values[i] = *value;
  }
  if (values[0] > values[1]) {
    table.fail(key, fmt::format("the first ({}) is after the last ({})", values[0], values[1]));
  }
  return {values[0], values[1]};
}

CalibrationDesignEntry read_design(detail::TableReader table) {
  CalibrationDesignEntry entry;
  entry.pooling = entry.asymmetry = false;
  const toml::array& tables = table.array("tables");
  if (tables.empty()) table.fail("tables", R"(expected "pooling", "asymmetry" or both)");
  for (const toml::node& element : tables) {
    const std::optional<std::string> name = element.value<std::string>();
    bool* measures = !name                  ? nullptr
                     : *name == "pooling"   ? &entry.pooling
                     : *name == "asymmetry" ? &entry.asymmetry
                                            : nullptr;
    if (measures == nullptr) {
      detail::fail_element(table.file(), table.key_path("tables"), element,
                           R"(expected "pooling" or "asymmetry")");
    }
    if (*measures) detail::fail_element(table.file(), table.key_path("tables"), element, "twice");
    *measures = true;
  }
  CalibrationDesign& design = entry.design;
  const toml::array& sizes = table.array("sizes");
  if (sizes.empty()) table.fail("sizes", "expected at least one insole size");
  for (const toml::node& element : sizes) {
    const std::optional<std::string> name = element.value<std::string>();
    const std::optional<InsoleSize> size = name ? parse_insole_size(*name) : std::nullopt;
    if (!size) {
      detail::fail_element(table.file(), table.key_path("sizes"), element,
                           "expected an insole size such as \"41-42\"");
    }
    design.sizes.push_back(*size);
  }
  const auto [first, last] = read_range(table, "seeds", 0.0, 1e15);
  if (first != std::floor(first) || last != std::floor(last)) {
    table.fail("seeds", "expected whole numbers");
  }
  design.first_seed = static_cast<std::uint64_t>(first);
  design.last_seed = static_cast<std::uint64_t>(last);
  design.duration_s = detail::number_in(table, "duration_s", 5.0, 3600.0);
  std::tie(design.min_body_mass_kg, design.max_body_mass_kg) =
      read_range(table, "body_mass_kg", 1.0, 300.0);
  if (table.has("noise_sd_bits")) {
    design.noise_sd_bits = detail::number_in(table, "noise_sd_bits", 0.0, 50.0);
  }
  if (table.has("max_bias_bits")) {
    design.max_bias_bits = detail::integer_in(table, "max_bias_bits", 0, 50);
  }
  if (table.has("placement_sd_mm")) {
    design.placement_sd_mm = detail::number_in(table, "placement_sd_mm", 0.0, 10.0);
  }
  if (table.has("rasterisation")) {
    const std::string raster = table.string("rasterisation");
    const std::optional<Rasterisation> parsed = parse_rasterisation(raster);
    if (!parsed) {
      table.fail("rasterisation",
                 fmt::format(R"(must be "centre" or "coverage", got "{}")", raster));
    }
    design.rasterisation = *parsed;
  }
  try {
    design.check();
  } catch (const std::invalid_argument& e) {
    table.fail_here(e.what());
  }
  table.finish();
  return entry;
}

}  // namespace

std::vector<CalibrationDesignEntry> load_calibration_designs(const fs::path& path) {
  const std::string file = path.string();
  const toml::table doc = detail::parse_document(path, file, "(file)");
  detail::TableReader root(doc, file, "");
  const toml::array& designs = root.array("design");
  if (designs.empty()) root.fail("design", "expected at least one [[design]]");
  std::vector<CalibrationDesignEntry> out;
  for (std::size_t i = 0; i < designs.size(); ++i) {
    const toml::table* table = designs.get(i)->as_table();
    if (table == nullptr) {
      detail::fail_element(file, "design", *designs.get(i), "expected a [[design]] table");
    }
    out.push_back(read_design(detail::TableReader(*table, file, fmt::format("design[{}]", i + 1))));
  }
  root.finish();
  return out;
}

CalibrationSamples collect_chain_samples(const Config& config, const CalibrationDesign& design,
                                         const fs::path& scratch_dir,
                                         const std::function<void(double)>& on_progress) {
  design.check();
  const std::size_t count = design.session_count();
  const fs::path dir = scratch_dir / "calibration-sessions";
  fs::create_directories(dir);
  std::vector<SessionSamples> results(count);
  std::vector<ContactEllipseCache> caches(detail::parallel_workers(count));
  try {
    detail::parallel_for_workers(
        count,
        [&](std::size_t i, std::size_t worker) {
          results[i] = run_session(config, design, i, dir, caches[worker]);
        },
        [&](std::size_t done) {
          if (on_progress) on_progress(static_cast<double>(done) / static_cast<double>(count));
        });
  } catch (...) {
    fs::remove_all(dir);
    throw;
  }
  fs::remove_all(dir);
  // The calling thread reports only the items it finished itself, which may not be the last.
  if (on_progress) on_progress(1.0);
  CalibrationSamples samples;
  samples.sessions = count;
  for (const SessionSamples& r : results) {
    append(r.per_step, samples.per_step);
    append(r.m_per_session, samples.m_per_session);
  }
  return samples;
}

double rms_z(const std::vector<ChainSample>& samples, double sd, double m_sd) {
  if (samples.empty()) return std::nan("");
  double sum = 0.0;
  for (const ChainSample& s : samples) {
    const double shared = s.slope_on_shared_m * m_sd;
    sum += s.error * s.error / (s.se_steps * s.se_steps + shared * shared + sd * sd);
  }
  return std::sqrt(sum / static_cast<double>(samples.size()));
}

std::optional<double> sd_for_unit_rms(const std::vector<ChainSample>& samples, double m_sd) {
  if (samples.empty()) return std::nullopt;
  if (rms_z(samples, 0.0, m_sd) <= 1.0) return 0.0;
  double lo = 0.0;
  double hi = kLargestSd;
  if (rms_z(samples, hi, m_sd) > 1.0) return hi;
  // To the double's resolution, so that rounding up to a step never catches a bisection's slack.
  for (int i = 0; i < 80 && lo < hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (rms_z(samples, mid, m_sd) > 1.0 ? lo : hi) = mid;
  }
  return hi;
}

double round_up_to(double value, double step) {
  const double steps = std::ceil(value / step - 1e-9);
  return steps > 0.0 ? steps * step : 0.0;  // never -0, which would print as "-0.0"
}

MeasuredChainSds measure_chain_sds(const ChainSamples& samples) {
  constexpr std::array<double, 4> kPercent = {100.0, 1.0, 100.0, 1.0};
  const auto rounded = [&](std::optional<double> sd, std::size_t p) -> std::optional<double> {
    if (!sd) return std::nullopt;
    return round_up_to(*sd * kPercent[p], kPercent[p] == 100.0 ? 0.5 : 0.005);
  };
  MeasuredChainSds out;
  for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
    const auto& pooled = samples.pooled[ri];
    out.chain[3][ri] = rounded(sd_for_unit_rms(pooled[3]), 3);
    const double m_sd = out.chain[3][ri].value_or(0.0);
    for (std::size_t p = 0; p < 3; ++p)
      out.chain[p][ri] = rounded(sd_for_unit_rms(pooled[p], m_sd), p);
    for (std::size_t p = 0; p < 4; ++p) {
      const std::optional<double> total = sd_for_unit_rms(samples.steps[ri][p], m_sd);
      if (!total) continue;
      const double chain = out.chain[p][ri].value_or(0.0) / kPercent[p];
      out.step[p][ri] = rounded(std::sqrt(std::max(0.0, *total * *total - chain * chain)), p);
    }
    for (std::size_t p = 0; p < 2; ++p)
      out.pair[p][ri] = rounded(sd_for_unit_rms(samples.feet[ri][p]), 0);
  }
  return out;
}

}  // namespace gaitmon
