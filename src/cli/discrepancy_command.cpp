// `gaitmon discrepancy`: where the fitted model and the session disagree, which missing effect
// explains it, and how far adding it closes the held-out gap (DIR/discrepancy.json, report).
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "commands.hpp"
#include "discrepancy_report.hpp"
#include "gaitmon/analysis.hpp"
#include "gaitmon/batch.hpp"
#include "gaitmon/discrepancy.hpp"
#include "gaitmon/error.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/json.hpp"
#include "gaitmon/session.hpp"
#include "output_file.hpp"
#include "progress.hpp"
#include "report_html.hpp"

namespace gaitmon::cli {
namespace {

struct DiscrepancyArgs {
  std::filesystem::path session;
  std::filesystem::path out_dir;
  bool report = false;
  std::string area = "auto";
  bool keep_creep = false;
  DiscrepancySettings settings;
};

// The area the fits were given, and how the session's cells read, which `auto` follows.
struct AreaUsed {
  AreaSource area = AreaSource::Footprint;
  CellReadingEvidence cells;
};

// " name=value+-se" per parameter, "(no SE)" where the data do not determine it, and the
// sandwich's error where it has one.
std::string params_text(const std::vector<ParamEstimate>& params) {
  std::string text;
  for (const ParamEstimate& p : params) {
    text += fmt::format(" {}={}", p.name, param_text(p, "+-"));
  }
  return text;
}

// The parameters show why a candidate with a clear gain may still not be named: one without
// a standard error (at a bound of its range, or along a flat direction) is not determined.
void print_candidates(const std::vector<CandidateResult>& list) {
  fmt::print("{:<20}{:>14}{:>12}{:>12}{:>12}  {}\n", "candidate", "held-out %", "shrink %",
             "zero shr. %", "dBIC", "parameters");
  for (const CandidateResult& c : list) {
    fmt::print("{:<20}{:>14.2f}{:>12.1f}{:>12.1f}{:>12.0f} {}\n", c.name, c.heldout_nrmse_pct,
               c.shrink_pct, c.zero_shrink_pct, c.delta_bic, params_text(c.params));
  }
}

nlohmann::json params_json(const std::vector<ParamEstimate>& params) {
  nlohmann::json j = nlohmann::json::object();
  for (const ParamEstimate& p : params) j[p.name] = p;
  return j;
}

nlohmann::json candidates_json(const std::vector<CandidateResult>& list) {
  nlohmann::json j = nlohmann::json::array();
  for (const CandidateResult& c : list) {
    j.push_back({{"name", c.name},
                 {"params", params_json(c.params)},
                 {"in_sample_nrmse_pct", c.in_sample_nrmse_pct},
                 {"heldout_nrmse_pct", c.heldout_nrmse_pct},
                 {"heldout_shrink_pct", c.shrink_pct},
                 {"zero_heldout_nrmse_pct", c.zero_heldout_nrmse_pct},
                 {"zero_heldout_shrink_pct", c.zero_shrink_pct},
                 {"heldout_deviance_drop", c.heldout_deviance_drop},
                 {"bic", c.bic},
                 {"delta_bic", c.delta_bic}});
  }
  return j;
}

nlohmann::json cell_json(const ResidualCell& c, int bins) {
  return {{"region", region_name(c.region)},
          {"phase_bin", c.bin},
          {"phase_from", static_cast<double>(c.bin) / bins},
          {"phase_to", static_cast<double>(c.bin + 1) / bins},
          {"samples", c.samples},
          {"residual_rms_n", c.rms_n},
          {"residual_bias_n", c.bias_n},
          {"noise_floor_n", c.noise_floor_n}};
}

nlohmann::json map_json(const ResidualMap& map) {
  nlohmann::json j = nlohmann::json::object();
  for (Region region : kRegions) {
    nlohmann::json rms = nlohmann::json::array(), bias = rms, floor = rms;
    for (const ResidualCell& c : map.cells) {
      if (c.region != region) continue;
      rms.push_back(c.rms_n);
      bias.push_back(c.bias_n);
      floor.push_back(c.noise_floor_n);
    }
    j[std::string(region_name(region))] = {
        {"residual_rms_n", rms}, {"residual_bias_n", bias}, {"noise_floor_n", floor}};
  }
  return j;
}

std::string discrepancy_json(const DiscrepancyArgs& args, const Config& config,
                             const AreaUsed& used, const DiscrepancyResult& r) {
  nlohmann::json j;
  j["session"] = args.session.filename().string();
  nlohmann::json named = nlohmann::json::array();
  nlohmann::json named_params = nlohmann::json::array();
  for (const EffectEstimate& e : r.named_effects) {
    named.push_back(e.name);
    named_params.push_back({{"name", e.name}, {"params", params_json(e.params)}});
  }
  j["named_effects"] = named;
  j["named_effect_params"] = named_params;
  j["most_likely_candidate"] = r.most_likely_candidate;
  j["not_named_reason"] = r.not_named_reason;
  j["baseline_heldout_nrmse_pct"] = r.baseline_heldout_nrmse_pct;
  j["extended_heldout_nrmse_pct"] = r.extended_heldout_nrmse_pct;
  j["gap_shrink_pct"] = r.gap_shrink_pct;
  j["zero_channel"] = {
      {"changes", r.zero_changes},
      {"baseline_heldout_nrmse_pct", r.zero_baseline_heldout_nrmse_pct},
      {"extended_heldout_nrmse_pct", r.zero_extended_heldout_nrmse_pct},
      {"gap_shrink_pct", r.zero_gap_shrink_pct},
      {"what",
       "change of each step-region's zero (its mean reading in the swing windows around "
       "the step) from the foot's step before, scaled by the step-region's peak force"}};
  j["noise_floor_nrmse_pct"] = r.noise_floor_nrmse_pct;
  j["nrmse_scale"] = {{"newtons", r.nrmse_scale_n},
                      {"what",
                       "an NRMSE of x % is an RMS residual of x / 100 times this: the root mean "
                       "square over the compared frames of their step-region's peak force"}};
  j["baseline_in_sample_nrmse_pct"] = r.baseline_in_sample_nrmse_pct;
  j["baseline_bic"] = r.baseline_bic;
  j["settings"] = {
      {"folds", args.settings.folds},
      {"phase_bins", args.settings.phase_bins},
      {"min_shrink_pct", args.settings.min_shrink_pct},
      {"min_zero_shrink_pct", args.settings.min_zero_shrink_pct},
      {"min_delta_bic", args.settings.min_delta_bic},
      {"min_ceiling_steps", args.settings.min_ceiling_steps},
      {"min_ceiling_steps_pct", args.settings.min_ceiling_steps_pct},
      {"min_neighbour_share", args.settings.min_neighbour_share},
      {"min_cell_coupling", args.settings.min_cell_coupling},
      {"second_effect", args.settings.second_effect},
      {"area", area_source_name(used.area)},
      {"area_auto", args.area == "auto"},
      {"sensor_creep_of_config",
       {{"gain", config.sensor_creep.gain}, {"tau_s", config.sensor_creep.tau_s}}},
      {"nrmse", "pooled eq 58: sqrt(sum r^2 / sum frames x peak^2) over step-regions"}};
  j["cell_reading"] = cell_reading_json(used.cells);
  j["data"] = {{"steps", r.steps},
               {"step_regions", r.step_regions},
               {"step_regions_left_out_ellipse_area", r.step_regions_left_out},
               {"frames", r.frames}};
  nlohmann::json where = nlohmann::json::array();
  for (const ResidualCell& c : r.where) where.push_back(cell_json(c, args.settings.phase_bins));
  j["where"] = where;
  j["candidates"] = candidates_json(r.candidates);
  j["second_candidates"] = candidates_json(r.second_candidates);
  j["second_candidates_on"] =
      r.creep_undone ? "the readings with the sensor creep undone" : "the first named effect";
  if (const auto& u = r.creep_undone) {
    j["creep_undone_in_readings"] = {
        {"params", params_json(u->creep.params)},
        {"steps", u->steps},
        {"baseline_heldout_nrmse_pct", u->baseline_heldout_nrmse_pct},
        {"most_likely_candidate", u->most_likely_candidate},
        {"not_named_reason", u->not_named_reason},
        {"what",
         "the zeros named a sensor creep: the session was read again with it undone in every "
         "frame, and one effect on top of it was looked for there; extended_heldout_nrmse_pct, "
         "residual_map_after and each region's and step's extended figure are of those readings, "
         "against their own peaks"}};
  } else {
    j["creep_undone_in_readings"] = nullptr;
  }
  nlohmann::json regions = nlohmann::json::object();
  for (const RegionComparison& c : r.regions) {
    regions[std::string(region_name(c.region))] = c;
  }
  j["regions"] = regions;
  j["residual_map_before"] = map_json(r.map_before);
  j["residual_map_after"] = map_json(r.map_after);
  nlohmann::json steps = nlohmann::json::array();
  for (const StepComparison& s : r.per_step) {
    steps.push_back({{"foot", foot_name(s.foot)},
                     {"step", s.step},
                     {"baseline_nrmse_pct", s.baseline_nrmse_pct},
                     {"extended_heldout_nrmse_pct", s.extended_nrmse_pct}});
  }
  j["steps"] = steps;
  const ResidualDiagnostics& d = r.diagnostics;
  nlohmann::json corr = nlohmann::json::object();
  for (const StateCorrelation& c : d.correlations) corr[c.state] = c.r;
  j["diagnostics"] = {{"bias_per_phase_pct_of_peak", d.bias_per_phase_pct},
                      {"lag1_autocorrelation", d.lag1_autocorrelation},
                      {"runs_test_z", d.runs_z},
                      {"effective_sample_fraction", d.effective_sample_fraction},
                      {"correlation_with_state", corr},
                      {"ceiling_plateau_steps", r.ceiling_plateau_steps},
                      {"neighbour_share",
                       {{"floor", r.neighbour_share.floor},
                        {"cell_frames", r.neighbour_share.cell_frames},
                        {"neighbours_read_at_least_bits", kNeighbourShareBits}}}};
  j["diagnostics"]["cell_coupling"] = {{"coupling", r.cell_coupling.coupling},
                                       {"frames", r.cell_coupling.frames}};
  nlohmann::json zeros = nlohmann::json::array();
  for (const ZeroLevelDrift& z : r.zero_levels) {
    zeros.push_back({{"foot", foot_name(z.foot)},
                     {"steps", z.steps},
                     {"first_bits", z.first_bits},
                     {"last_bits", z.last_bits},
                     {"lowest_bits", z.lowest_bits},
                     {"highest_bits", z.highest_bits},
                     {"scatter_bits", z.scatter_bits},
                     {"range_pct_of_peak", z.range_pct_of_peak},
                     {"drifting", z.drifting},
                     {"t_s", z.t_s},
                     {"zero_bits", z.zero_bits}});
  }
  j["diagnostics"]["zero_levels"] = zeros;
  return json_file_text(j);
}

void run_discrepancy(const GlobalOptions& global, const DiscrepancyArgs& args) {
  const Config config = load_global_config(global);
  check_output_dir(args.out_dir, "--out");
  OutputSet outputs(args.out_dir, {"discrepancy.json", "discrepancy.html"},
                    std::span(&args.session, 1));
  const SessionHeader header = SessionReader(args.session).header();
  const InsoleLayout layout(config.insole(header.insole_size), config.sensor);
  DiscrepancyResult result;
  AreaUsed used;
  {
    ProgressBar progress("discrepancy");
    // The complete steps of the session, each frame corrected first where `correct_frame` is set.
    const auto read_steps = [&](const std::function<void(double)>& on_progress,
                                const std::function<void(Frame&)>& correct_frame) {
      std::vector<Step> steps;
      segment_session(
          args.session, config,
          [&](Step&& step) {
            if (step.status == StepStatus::Ok) steps.push_back(std::move(step));
          },
          on_progress, correct_frame);
      if (static_cast<int>(steps.size()) < args.settings.folds) {
        throw InputError(
            args.session.string(), 0,
            fmt::format("{} complete steps{}, need at least {} (one per fold of --folds)",
                        steps.size(), correct_frame ? " with the sensor creep undone" : "",
                        args.settings.folds));
      }
      return steps;
    };
    const std::vector<Step> steps =
        read_steps([&](double fraction) { progress.update(0.1 * fraction); }, {});
    used.cells = cell_reading_evidence(steps, layout);
    used.area = args.area == "auto" ? footprint_for(used.cells) : *parse_area_source(args.area);
    AnalysisSettings analysis = discrepancy_analysis_settings();
    analysis.area = used.area;
    const DiscrepancyInput input = prepare_discrepancy_input(steps, layout, config, analysis);
    progress.update(0.3);
    const auto on_progress = [&](double fraction) { progress.update(0.3 + 0.7 * fraction); };
    result = args.keep_creep
                 ? find_discrepancy(input, args.settings, on_progress)
                 : find_discrepancy_undoing_creep(
                       input,
                       [&](CreepCorrection creep) {
                         const std::vector<Step> undone =
                             read_steps({}, [&](Frame& frame) { creep.undo(frame); });
                         return prepare_discrepancy_input(undone, layout, config, analysis);
                       },
                       args.settings, on_progress);
  }

  std::filesystem::create_directories(args.out_dir);
  outputs.add("discrepancy.json", discrepancy_json(args, config, used, result));
  if (args.report) {
    outputs.add("discrepancy.html",
                render_discrepancy_html(args.session.filename().string(), result));
  }
  const std::vector<std::filesystem::path> written = outputs.commit();

  fmt::print(
      "{}: {} steps, {} step-regions ({} left out: their cells give no footprint); noise floor "
      "{:.1f} %; an NRMSE of 1 % is {:.2f} N RMS\n",
      args.session.string(), result.steps, result.step_regions, result.step_regions_left_out,
      result.noise_floor_nrmse_pct, result.nrmse_scale_n / 100.0);
  fmt::print("cells: {}; area {}{}\n", cell_reading_sentence(used.cells),
             area_source_name(used.area), args.area == "auto" ? " (auto)" : "");
  if (const std::string advice = cell_reading_advice(used.cells, used.area); !advice.empty()) {
    fmt::print("note: {}\n", advice);
  }
  print_candidates(result.candidates);
  if (const auto& u = result.creep_undone) {
    fmt::print(
        "sensor creep undone in the readings ({}): the session read again gives {} steps and a "
        "baseline held-out NRMSE of {:.2f} % ({:.2f} % as read); one effect on top of it:\n",
        params_text(u->creep.params).substr(1), u->steps, u->baseline_heldout_nrmse_pct,
        result.baseline_heldout_nrmse_pct);
    print_candidates(result.second_candidates);
  }
  if (result.ceiling_plateau_steps >= 0) {
    fmt::print(
        "ceiling in the readings: {} of {} steps have a frame with two or more cells of one "
        "region at the session's top reading (sensor_saturation needs {} and {:.0f} %)\n",
        result.ceiling_plateau_steps, result.steps, args.settings.min_ceiling_steps,
        args.settings.min_ceiling_steps_pct);
  }
  if (result.neighbour_share.cell_frames > 0) {
    fmt::print(
        "crosstalk in the readings: 1 % of {} cells next to loaded ones (their neighbours read "
        "{:g} bits or more) read under {:.3f} of their neighbours' readings (crosstalk needs "
        "{:g})\n",
        result.neighbour_share.cell_frames, kNeighbourShareBits, result.neighbour_share.floor,
        args.settings.min_neighbour_share);
  }
  if (result.cell_coupling.frames > 0) {
    fmt::print(
        "crosstalk in the cells: over {} region-frames their readings fit their caps best with a "
        "coupling of {:.3f} undone (crosstalk needs {:g})\n",
        result.cell_coupling.frames, result.cell_coupling.coupling,
        args.settings.min_cell_coupling);
  }
  std::string named;
  for (const EffectEstimate& e : result.named_effects) {
    named += (named.empty() ? "" : ", ") + e.name + params_text(e.params);
  }
  if (!result.not_named_reason.empty()) {
    named = fmt::format("{} (the most likely candidate, {}, is not named: {})",
                        named.empty() ? "none" : named, result.most_likely_candidate,
                        result.not_named_reason);
  }
  fmt::print("named: {}\n", named);
  for (const ZeroLevelDrift& z : result.zero_levels) {
    if (!z.drifting) continue;
    fmt::print(
        "zero level of foot {}: {:.0f} -> {:.0f} bits over {} steps, range {:.1f} % of the peak, "
        "step-to-step scatter {:.1f} bits: the readings drift (sensor creep or thermal drift); "
        "the zeroing at each step's swings takes it out of the force\n",
        foot_name(z.foot), z.first_bits, z.last_bits, z.steps, z.range_pct_of_peak, z.scatter_bits);
  }
  fmt::print("held-out NRMSE {:.2f} % -> {:.2f} % (gap shrink {:.1f} %){}\n",
             result.baseline_heldout_nrmse_pct, result.extended_heldout_nrmse_pct,
             result.gap_shrink_pct,
             result.creep_undone ? ", the second on the readings with the creep undone" : "");
  if (result.zero_changes > 0) {
    fmt::print(
        "zero channel ({} step-to-step changes of the zero): held-out NRMSE {:.3f} % -> "
        "{:.3f} % (gap shrink {:.1f} %)\n",
        result.zero_changes, result.zero_baseline_heldout_nrmse_pct,
        result.zero_extended_heldout_nrmse_pct, result.zero_gap_shrink_pct);
  }
  for (const EffectEstimate& e : result.named_effects) {
    if (!effect_undone_in_readings(e, result.zero_gap_shrink_pct,
                                   args.settings.min_zero_shrink_pct)) {
      continue;
    }
    if (result.creep_undone) {
      fmt::print(
          "note: creep also reshapes each step's footprint; the extended figures above are of the "
          "readings with it undone, and gaitmon analyze --effects sensor_creep measures and fits "
          "every step from them\n");
      const CreepCorrection creep = creep_correction(e);
      fmt::print("{}\n", sensor_creep_advice(config, creep.gain(), creep.tau_s()));
    } else {
      fmt::print(
          "note: creep also reshapes each step's footprint, which the force figures above leave "
          "to the baseline (--keep-creep); gaitmon analyze --effects sensor_creep undoes it in "
          "the readings and measures every step again\n");
    }
  }
  for (const auto& path : written) fmt::print("wrote {}\n", path.string());
}

}  // namespace

void add_discrepancy_command(CLI::App& app, const GlobalOptions& global) {
  auto args = std::make_shared<DiscrepancyArgs>();
  CLI::App* sub = app.add_subcommand(
      "discrepancy",
      "Find where the fitted tissue model and the session disagree, name the missing effect "
      "and show the held-out gap shrink: writes DIR/discrepancy.json and, with --report, "
      "DIR/discrepancy.html");
  sub->add_option("session", args->session, "Session CSV v1")
      ->required()
      ->check(session_file_read_twice());
  sub->add_option("--out,-o", args->out_dir, "Output folder")->required();
  sub->add_flag("--report", args->report, "Also write a self-contained HTML report");
  sub->add_flag("--keep-creep", args->keep_creep,
                "Where the zeros name a sensor creep, look for further effects on the readings as "
                "read; by default the session is read again with the creep undone and they are "
                "looked for there");
  sub->add_option("--area", args->area,
                  "Contact area given to the fits: auto (footprint-mean where the session's "
                  "readings fit cells that average the pressure better, else footprint, as "
                  "analyze's auto), footprint or footprint-mean. On cells that average, the "
                  "footprint over-reads the area and the neighbours' share of the load reads as "
                  "crosstalk")
      ->check(CLI::IsMember({"auto", "footprint", "footprint-mean"}))
      ->capture_default_str();
  sub->add_option("--folds", args->settings.folds, "k of the k-fold over steps")
      ->check(CLI::Range(2, 20))
      ->capture_default_str();
  sub->add_option("--phase-bins", args->settings.phase_bins, "Bins of normalised stance time")
      ->check(CLI::Range(10, 100))
      ->capture_default_str();
  sub->add_option("--min-shrink", args->settings.min_shrink_pct,
                  "Held-out NRMSE fall needed to name an effect, %")
      ->check(number_in(0.0, 100.0))
      ->capture_default_str();
  sub->add_option("--min-zero-shrink", args->settings.min_zero_shrink_pct,
                  "Held-out NRMSE fall of the zero changes needed to name an effect, %")
      ->check(number_in(0.0, 100.0))
      ->capture_default_str();
  sub->add_option("--min-delta-bic", args->settings.min_delta_bic,
                  "BIC fall needed to name an effect")
      ->check(number_in(0.0, 1e6))
      ->capture_default_str();
  sub->callback([&global, args] { run_discrepancy(global, *args); });
}

}  // namespace gaitmon::cli
