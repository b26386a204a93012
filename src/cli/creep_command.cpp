// `gaitmon creep`: the sensor creep of one pair of insoles, measured on several of its recordings
// as `analyze --effects sensor_creep` measures it, and whether they agree on one creep before it
// goes into the config's [sensor_creep].
#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "commands.hpp"
#include "gaitmon/analysis.hpp"
#include "gaitmon/batch.hpp"
#include "gaitmon/creep.hpp"
#include "gaitmon/discrepancy.hpp"
#include "gaitmon/error.hpp"
#include "gaitmon/insole.hpp"
#include "gaitmon/session.hpp"
#include "progress.hpp"

namespace gaitmon::cli {
namespace {

namespace fs = std::filesystem;

struct CreepArgs {
  std::vector<fs::path> sessions;
  double min_p = 0.01;
};

/// One recording's creep on top of the config's, and whether its zeros show it.
struct RecordingCreep {
  fs::path session;
  std::size_t steps = 0;
  MeasuredCreep creep;
  double zero_before_pct = 0.0;  ///< the zero channel's held-out NRMSE without and with it
  double zero_after_pct = 0.0;
  bool shown = false;  ///< effect_undone_in_readings: the zeros show it and the data determine it
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
  for (const ParamEstimate& p : fit.effects.front().params) {
    if (p.name == "gain") {
      out.creep.gain = p.value;
      out.creep.gain_se = p.se;
    } else if (p.name == "tau_s") {
      out.creep.tau_s = p.value;
      out.creep.tau_se_s = p.se;
    }
  }
  out.zero_before_pct = fit.zero_baseline_heldout_nrmse_pct;
  out.zero_after_pct = fit.zero_extended_heldout_nrmse_pct;
  out.shown = effect_undone_in_readings(fit, fit.effects.front());
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
  std::vector<RecordingCreep> recordings;
  {
    ProgressBar progress("creep");
    for (const fs::path& session : args.sessions) {
      recordings.push_back(measure_creep(session, config));
      progress.update(static_cast<double>(recordings.size()) /
                      static_cast<double>(args.sessions.size()));
    }
  }

  const std::string on_top =
      config.sensor_creep.gain > 0.0
          ? fmt::format(" on top of the config's [sensor_creep] (gain {:.4g}, tau {:.4g} s)",
                        config.sensor_creep.gain, config.sensor_creep.tau_s)
          : "";
  fmt::print("sensor creep of each recording{}, as analyze --effects sensor_creep fits it:\n",
             on_top);
  fmt::print("{:<32} {:>5}  {:<20} {:<20} {:<24} {}\n", "recording", "steps", "gain", "tau_s",
             "zero channel held out", "shows it");
  std::vector<MeasuredCreep> shown;
  for (const RecordingCreep& r : recordings) {
    fmt::print("{:<32} {:>5}  {:<20} {:<20} {:<24} {}\n", r.session.filename().string(), r.steps,
               estimate_text(r.creep.gain, r.creep.gain_se, " +- "),
               estimate_text(r.creep.tau_s, r.creep.tau_se_s, " +- "),
               fmt::format("{:.3f} -> {:.3f} %", r.zero_before_pct, r.zero_after_pct),
               r.shown ? "yes" : "no");
    if (r.shown) shown.push_back(r.creep);
  }
  const DiscrepancySettings rule;
  if (shown.size() < recordings.size()) {
    fmt::print(
        "note: \"shows it\" is no where the zero channel predicts the held-out steps less than "
        "{:.0f} % better with the creep, or its gain or tau has no standard error: analyze would "
        "not undo it there\n",
        rule.min_zero_shrink_pct);
  }
  if (shown.empty()) {
    fmt::print("no recording shows a creep{}: nothing to put in the config\n", on_top);
    return;
  }
  if (shown.size() == 1) {
    fmt::print(
        "one recording shows a creep{}: one walk cannot tell a creep of the insoles from one of "
        "that walk; measure it on another recording of the same pair\n",
        on_top);
    return;
  }
  const CreepAgreement a = creep_agreement(shown, args.min_p);
  fmt::print(
      "the {} recordings that show it, weighted by their standard errors: gain {}, tau {} s\n"
      "  spread against those errors: gain chi-square {:.3g} on {} degrees of freedom (p {:.3g}), "
      "tau chi-square {:.3g} (p {:.3g})\n",
      a.recordings, estimate_text(a.mean.gain, a.mean.gain_se, " +- "),
      estimate_text(a.mean.tau_s, a.mean.tau_se_s, " +- "), a.gain_chi2, a.recordings - 1, a.gain_p,
      a.tau_chi2, a.tau_p);
  if (!a.agree) {
    fmt::print(
        "they disagree (p under {:.3g}): not one creep of the insoles, so nothing to put in the "
        "config; what differs between the walks (the subject, the pair, how long the insoles had "
        "been worn) may be what the zeros follow\n",
        args.min_p);
    return;
  }
  fmt::print("they agree on one creep{}\n", on_top);
  fmt::print("{}\n", sensor_creep_advice(config, a.mean.gain, a.mean.tau_s));
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
  sub->callback([&global, args] { run_creep(global, *args); });
}

}  // namespace gaitmon::cli
