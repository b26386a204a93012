// `gaitmon creep`: the sensor creep of one pair of insoles, measured on several of its recordings
// as `analyze --effects sensor_creep` measures it, and whether they agree on one creep before it
// goes into the config's [sensor_creep]; with --out, creep.json and (--report) creep.html.
#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "commands.hpp"
#include "creep_report.hpp"
#include "gaitmon/analysis.hpp"
#include "gaitmon/batch.hpp"
#include "gaitmon/creep.hpp"
#include "gaitmon/discrepancy.hpp"
#include "gaitmon/error.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/session.hpp"
#include "output_file.hpp"
#include "progress.hpp"

namespace gaitmon::cli {
namespace {

namespace fs = std::filesystem;

constexpr std::string_view kJson = "creep.json";
constexpr std::string_view kHtml = "creep.html";

struct CreepArgs {
  std::vector<fs::path> sessions;
  double min_p = 0.01;
  fs::path out_dir;  ///< empty: stdout only
  bool report = false;
};

RecordingCreep measure_creep(const fs::path& session, const Config& config) {
  const SessionHeader header = SessionReader(session).header();
  const InsoleLayout layout(config.insole(header.insole_size), config.sensor);
  std::vector<Step> steps;
  segment_session(session, config, [&](Step&& step) {
    if (step.status == StepStatus::Ok) steps.push_back(std::move(step));
  });
  const int folds = DiscrepancySettings{}.folds;
  if (static_cast<int>(steps.size()) < folds) {
    throw InputError(session.string(), 0,
                     fmt::format("{} complete steps, need at least {} to fit a creep held out "
                                 "over {} folds",
                                 steps.size(), folds, folds));
  }
  // As analyze takes its area by default, so that both print one creep for one recording.
  AnalysisSettings settings;
  const std::optional<AreaSource> area = parse_area_source(config.model.area);
  settings.area = area ? *area : footprint_for(cell_reading_evidence(steps, layout));
  const std::vector<std::string> names{"sensor_creep"};
  const ExtendedModelFit fit =
      fit_extended_model(extended_model_input(steps, analyse_steps(steps, layout, config, settings),
                                              layout, config, names, settings.area),
                         names);
  RecordingCreep out;
  out.session = session;
  out.steps = steps.size();
  ParamEstimate gain, tau;
  for (const ParamEstimate& p : fit.effects.front().params) (p.name == "gain" ? gain : tau) = p;
  out.creep = larger_errors(gain, tau);
  out.curvature = {gain.value, gain.se, tau.value, tau.se};
  out.sandwich = {gain.value, gain.robust_se, tau.value, tau.robust_se};
  out.zero_before_pct = fit.zero_baseline_heldout_nrmse_pct;
  out.zero_after_pct = fit.zero_extended_heldout_nrmse_pct;
  out.shown = effect_undone_in_readings(fit, fit.effects.front());
  out.cells_at_zero_pct = loaded_cells_at_zero(steps).pct();
  return out;
}

void run_creep(const GlobalOptions& global, const CreepArgs& args) {
  const Config config = load_global_config(global);
  for (std::size_t i = 0; i < args.sessions.size(); ++i) {
    for (std::size_t j = 0; j < i; ++j) {
      if (fs::equivalent(args.sessions[i], args.sessions[j])) {
        throw CLI::ValidationError(
            "session", fmt::format("{} is given twice (as {}): one walk would count as two",
                                   args.sessions[i].string(), args.sessions[j].string()));
      }
    }
  }
  std::optional<OutputSet> outputs;
  if (!args.out_dir.empty()) {
    check_output_dir(args.out_dir, "--out");
    outputs.emplace(args.out_dir, std::initializer_list<std::string_view>{kJson, kHtml},
                    args.sessions);
  }
  CreepFindings found;
  found.config_creep = config.sensor_creep;
  found.min_p = args.min_p;
  {
    ProgressBar progress("creep");
    for (const fs::path& session : args.sessions) {
      found.recordings.push_back(measure_creep(session, config));
      progress.update(static_cast<double>(found.recordings.size()) /
                      static_cast<double>(args.sessions.size()));
    }
  }
  std::vector<MeasuredCreep> shown;
  for (const RecordingCreep& r : found.recordings) {
    if (r.shown) shown.push_back(r.creep);
  }
  if (shown.size() >= 2) found.agreement = creep_agreement(shown, args.min_p);
  if (found.verdict() == CreepVerdict::Agree) {
    found.advice =
        sensor_creep_advice(config, found.agreement->mean.gain, found.agreement->mean.tau_s);
  }

  fmt::print(
      "sensor creep of each recording{}, as analyze --effects sensor_creep fits it (+- the larger "
      "of the curvature's and the step-clustered sandwich's standard errors):\n",
      on_top_of_config(found.config_creep));
  fmt::print("{:<32} {:>5}  {:<20} {:<20} {:<24} {:<8}  {}\n", "recording", "steps", "gain",
             "tau_s", "zero channel held out", "shows it", "cells at 0");
  for (const RecordingCreep& r : found.recordings) {
    fmt::print("{:<32} {:>5}  {:<20} {:<20} {:<24} {:<8}  {:.0f} %\n",
               r.session.filename().string(), r.steps,
               estimate_text(r.creep.gain, r.creep.gain_se, " +- "),
               estimate_text(r.creep.tau_s, r.creep.tau_se_s, " +- "),
               fmt::format("{:.3f} -> {:.3f} %", r.zero_before_pct, r.zero_after_pct),
               r.shown ? "yes" : "no", r.cells_at_zero_pct);
  }
  if (shown.size() < found.recordings.size()) {
    fmt::print(
        "note: \"shows it\" is no where the zero channel predicts the held-out steps less than "
        "{:.0f} % better with the creep, or its gain or tau has no standard error: analyze would "
        "not undo it there\n",
        DiscrepancySettings{}.min_zero_shrink_pct);
  }
  if (const std::string note = cells_at_zero_note(found.recordings); !note.empty()) {
    fmt::print("{}\n", note);
  }
  if (found.agreement) fmt::print("{}\n", agreement_text(*found.agreement, found.recordings));
  fmt::print("{}\n", verdict_text(found));
  if (!found.advice.empty()) fmt::print("{}\n", found.advice);
  if (outputs) {
    fs::create_directories(args.out_dir);
    outputs->add(kJson, creep_json_text(found));
    if (args.report) outputs->add(kHtml, render_creep_html(found));
    for (const fs::path& written : outputs->commit()) fmt::print("wrote {}\n", written.string());
  }
}

}  // namespace

void add_creep_command(CLI::App& app, const GlobalOptions& global) {
  auto args = std::make_shared<CreepArgs>();
  CLI::App* sub = app.add_subcommand(
      "creep",
      "Measure the sensor creep of one pair of insoles on several of its recordings, say whether "
      "they agree on one creep, and where they do print the config's [sensor_creep] to paste");
  sub->add_option("sessions", args->sessions,
                  "Session CSVs recorded with the same pair of insoles (two or more to judge "
                  "whether they agree)")
      ->required()
      ->check(session_file_read_twice());
  sub->add_option("--min-p", args->min_p,
                  "The chance below which the recordings' spread of gain or tau, against their "
                  "standard errors, says they are not one creep")
      ->check(number_in(0.0, 1.0, true))
      ->capture_default_str();
  CLI::Option* out = sub->add_option(
      "--out,-o", args->out_dir,
      "Output folder for creep.json (each recording's creep, their agreement and the section to "
      "paste)");
  sub->add_flag("--report", args->report,
                "Also write creep.html there: each recording's gain and tau with their 95 % "
                "intervals beside the weighted mean")
      ->needs(out);
  sub->callback([&global, args] { run_creep(global, *args); });
}

}  // namespace gaitmon::cli
