// creep.json and creep.html of `gaitmon creep`.
#include "creep_report.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "gaitmon/json.hpp"
#include "html.hpp"

namespace gaitmon::cli {
namespace {

// 95 % of a normal estimate lies within this many standard errors.
constexpr double kZ95 = 1.96;

nlohmann::json finite_or_null(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

nlohmann::json measured_json(const MeasuredCreep& c) {
  return {{"gain", c.gain},
          {"gain_se", finite_or_null(c.gain_se)},
          {"tau_s", c.tau_s},
          {"tau_se_s", finite_or_null(c.tau_se_s)}};
}

// One panel of the forest plot: each recording's value with its 95 % interval, those whose
// zeros do not show a creep in grey (they are not in the mean), and the weighted mean's 95 % band.
std::string forest_panel(const CreepFindings& f, const std::string& title,
                         double MeasuredCreep::*value, double MeasuredCreep::*se) {
  constexpr int kLabelW = 240, kPlotW = 440, kRowH = 22, kTop = 30, kBottom = 40;
  const int rows = static_cast<int>(f.recordings.size());
  const int height = kTop + rows * kRowH + kBottom;
  const int width = kLabelW + kPlotW + 20;
  double lo = INFINITY, hi = -INFINITY;
  const auto cover = [&](double v, double s) {
    const double half = std::isfinite(s) ? kZ95 * s : 0.0;
    lo = std::min(lo, v - half);
    hi = std::max(hi, v + half);
  };
  for (const RecordingCreep& r : f.recordings) cover(r.creep.*value, r.creep.*se);
  if (f.agreement) cover(f.agreement->mean.*value, f.agreement->mean.*se);
  const double span = hi - lo;
  const double pad = span > 0.0 ? 0.06 * span : std::max(0.1 * std::abs(lo), 1e-3);
  lo -= pad;
  hi += pad;
  const auto px = [&](double v) { return kLabelW + (v - lo) / (hi - lo) * kPlotW; };
  const int bottom = kTop + rows * kRowH;

  std::string svg = fmt::format(
      R"(<svg xmlns="http://www.w3.org/2000/svg" width="{0}" height="{1}" viewBox="0 0 {0} {1}" )"
      R"(role="img"><text x="{2}" y="18" text-anchor="middle" font-weight="bold">{3}</text>)"
      R"(<rect x="{4}" y="{5}" width="{6}" height="{7}" fill="none" stroke="#888"/>)",
      width, height, kLabelW + kPlotW / 2, escape(title), kLabelW, kTop, kPlotW, rows * kRowH);
  const double step = nice_step(hi - lo, 6);
  for (double t = std::ceil(lo / step) * step; t <= hi; t += step) {
    fmt::format_to(std::back_inserter(svg),
                   R"(<line x1="{0:.1f}" x2="{0:.1f}" y1="{1}" y2="{2}" stroke="#e4e4e4"/>)"
                   R"(<text x="{0:.1f}" y="{3}" text-anchor="middle" font-size="12">{4:g}</text>)",
                   px(t), kTop, bottom, bottom + 15, std::abs(t) < 1e-9 * step ? 0.0 : t);
  }
  if (f.agreement) {
    const double m = f.agreement->mean.*value;
    const double s = f.agreement->mean.*se;
    const double left = px(m - kZ95 * s);
    fmt::format_to(std::back_inserter(svg),
                   R"(<rect class="mean-band" x="{0:.1f}" y="{1}" width="{2:.1f}" height="{3}" )"
                   R"(fill="#d62728" fill-opacity="0.15"/>)"
                   R"(<line class="mean" x1="{4:.1f}" x2="{4:.1f}" y1="{1}" y2="{5}" )"
                   R"(stroke="#d62728" stroke-width="2"/>)",
                   left, kTop, std::max(1.0, px(m + kZ95 * s) - left), rows * kRowH, px(m), bottom);
  }
  for (int i = 0; i < rows; ++i) {
    const RecordingCreep& r = f.recordings[static_cast<std::size_t>(i)];
    const double y = kTop + (i + 0.5) * kRowH;
    const std::string colour = r.shown ? "#1f77b4" : "#999999";
    std::string name = r.session.filename().string();
    if (name.size() > 34) name = "..." + name.substr(name.size() - 31);
    fmt::format_to(std::back_inserter(svg),
                   R"(<text x="{}" y="{:.1f}" text-anchor="end" font-size="12">{}</text>)",
                   kLabelW - 8, y + 4, escape(name));
    const double v = r.creep.*value;
    const double s = r.creep.*se;
    if (std::isfinite(s)) {
      fmt::format_to(
          std::back_inserter(svg),
          R"(<line class="interval" x1="{0:.1f}" x2="{1:.1f}" y1="{2:.1f}" y2="{2:.1f}" )"
          R"(stroke="{3}" stroke-width="2"/>)",
          px(v - kZ95 * s), px(v + kZ95 * s), y, colour);
    }
    // Hollow where there is no standard error: the data do not determine that value.
    fmt::format_to(std::back_inserter(svg),
                   R"(<circle class="estimate" cx="{:.1f}" cy="{:.1f}" r="4" fill="{}" )"
                   R"(stroke="{}"/>)",
                   px(v), y, std::isfinite(s) ? colour : "#ffffff", colour);
  }
  return svg + "</svg>";
}

}  // namespace

CreepVerdict CreepFindings::verdict() const {
  if (agreement) return agreement->agree ? CreepVerdict::Agree : CreepVerdict::Disagree;
  const auto shown = std::count_if(recordings.begin(), recordings.end(),
                                   [](const RecordingCreep& r) { return r.shown; });
  return shown == 0 ? CreepVerdict::NoneShows : CreepVerdict::OneShows;
}

std::string_view verdict_name(CreepVerdict v) {
  switch (v) {
    case CreepVerdict::NoneShows:
      return "none_shows";
    case CreepVerdict::OneShows:
      return "one_shows";
    case CreepVerdict::Disagree:
      return "disagree";
    case CreepVerdict::Agree:
      return "agree";
  }
  return "";
}

MeasuredCreep larger_errors(const ParamEstimate& gain, const ParamEstimate& tau) {
  const auto larger = [](const ParamEstimate& p) {
    return std::isfinite(p.robust_se) ? std::max(p.se, p.robust_se) : p.se;
  };
  return {gain.value, larger(gain), tau.value, larger(tau)};
}

std::string on_top_of_config(const SensorCreepSettings& config_creep) {
  return config_creep.gain > 0.0
             ? fmt::format(" on top of the config's [sensor_creep] (gain {:.4g}, tau {:.4g} s)",
                           config_creep.gain, config_creep.tau_s)
             : "";
}

std::string agreement_text(const CreepAgreement& a, std::span<const RecordingCreep> recordings) {
  double gain_lo = INFINITY, gain_hi = -INFINITY, tau_lo = INFINITY, tau_hi = -INFINITY;
  for (const RecordingCreep& r : recordings) {
    if (!r.shown) continue;
    gain_lo = std::min(gain_lo, r.creep.gain);
    gain_hi = std::max(gain_hi, r.creep.gain);
    tau_lo = std::min(tau_lo, r.creep.tau_s);
    tau_hi = std::max(tau_hi, r.creep.tau_s);
  }
  return fmt::format(
      "the {} recordings that show it, weighted by their standard errors: gain {}, tau {} s\n"
      "  their gains span {:.4g} to {:.4g}, their taus {:.4g} to {:.4g} s\n"
      "  spread against those errors: gain chi-square {:.3g} on {} degrees of freedom (p {:.3g}), "
      "tau chi-square {:.3g} (p {:.3g})",
      a.recordings, estimate_text(a.mean.gain, a.mean.gain_se, " +- "),
      estimate_text(a.mean.tau_s, a.mean.tau_se_s, " +- "), gain_lo, gain_hi, tau_lo, tau_hi,
      a.gain_chi2, a.recordings - 1, a.gain_p, a.tau_chi2, a.tau_p);
}

std::string verdict_text(const CreepFindings& f) {
  const std::string on_top = on_top_of_config(f.config_creep);
  switch (f.verdict()) {
    case CreepVerdict::NoneShows:
      return fmt::format("no recording shows a creep{}: nothing to put in the config", on_top);
    case CreepVerdict::OneShows:
      return fmt::format(
          "one recording shows a creep{}: one walk cannot tell a creep of the insoles from one of "
          "that walk; measure it on another recording of the same pair",
          on_top);
    case CreepVerdict::Disagree:
      return fmt::format(
          "they disagree (p under {:.3g}): not one creep of the insoles, so nothing to put in the "
          "config; what differs between the walks (the subject, the pair, how long the insoles had "
          "been worn) may be what the zeros follow",
          f.min_p);
    case CreepVerdict::Agree:
      return fmt::format("they agree on one creep{}", on_top);
  }
  return "";
}

std::string cells_at_zero_note(std::span<const RecordingCreep> recordings) {
  std::size_t many = 0;
  double most = 0.0;
  for (const RecordingCreep& r : recordings) {
    if (r.cells_at_zero_pct >= kCellsAtZeroNotePct) ++many;
    most = std::max(most, r.cells_at_zero_pct);
  }
  if (many == 0) return "";
  return fmt::format(
      "note: in {} of the {} recordings {:.0f} % or more of the cells the steps loaded rest at 0 "
      "in the swing (up to {:.0f} %). A reading is clipped at 0, so their zeros show less of the "
      "creep than they hold, and the gain comes out low: on simulated walks of gain 0.2 with "
      "noise of 0.5 bits by 3 % where 9 % of them rested at 0, by 8.5 % where 25 % did, and by "
      "nothing where none did (README, \"Sensor creep of the insoles\")",
      many, recordings.size(), kCellsAtZeroNotePct, most);
}

std::string creep_json_text(const CreepFindings& f) {
  nlohmann::json recordings = nlohmann::json::array();
  for (const RecordingCreep& r : f.recordings) {
    nlohmann::json j = measured_json(r.creep);
    j["gain_se_curvature"] = finite_or_null(r.curvature.gain_se);
    j["gain_se_sandwich"] = finite_or_null(r.sandwich.gain_se);
    j["tau_se_curvature_s"] = finite_or_null(r.curvature.tau_se_s);
    j["tau_se_sandwich_s"] = finite_or_null(r.sandwich.tau_se_s);
    j["session"] = r.session.string();
    j["steps"] = r.steps;
    j["zero_baseline_heldout_nrmse_pct"] = r.zero_before_pct;
    j["zero_extended_heldout_nrmse_pct"] = r.zero_after_pct;
    j["shows_creep"] = r.shown;
    j["loaded_cells_at_zero_pct"] = r.cells_at_zero_pct;
    recordings.push_back(std::move(j));
  }
  nlohmann::json agreement = nullptr;
  if (f.agreement) {
    const CreepAgreement& a = *f.agreement;
    agreement = {{"recordings", a.recordings},
                 {"weighted_mean", measured_json(a.mean)},
                 {"degrees_of_freedom", a.recordings - 1},
                 {"gain_chi2", a.gain_chi2},
                 {"gain_p", a.gain_p},
                 {"tau_chi2", a.tau_chi2},
                 {"tau_p", a.tau_p},
                 {"agree", a.agree}};
  }
  const CreepVerdict v = f.verdict();
  nlohmann::json paste = nullptr;
  if (v == CreepVerdict::Agree) {
    paste = {{"gain", f.agreement->mean.gain}, {"tau_s", f.agreement->mean.tau_s}};
  }
  const nlohmann::json j = {
      {"config_sensor_creep", {{"gain", f.config_creep.gain}, {"tau_s", f.config_creep.tau_s}}},
      {"min_p", f.min_p},
      {"recordings", std::move(recordings)},
      {"agreement", std::move(agreement)},
      {"verdict", verdict_name(v)},
      {"sensor_creep_to_paste", std::move(paste)}};
  return json_file_text(j);
}

std::string render_creep_html(const CreepFindings& f) {
  std::string html = page_head(fmt::format("gaitmon creep: {} recordings", f.recordings.size()));
  html += fmt::format("<h1>Sensor creep of one pair of insoles: {} recordings</h1>",
                      f.recordings.size());
  html += fmt::format(
      "<p>Each recording's creep{}, as <code>analyze --effects sensor_creep</code> fits it: a held "
      "load reads 1 + gain of its value after a few tau. The intervals are 95 % (1.96 standard "
      "errors, each the larger of the deviance curvature's and the step-clustered sandwich's). "
      "Grey: the recording's zeros do not show the creep (it is left out of the mean); "
      "hollow: no standard error. Red: the recordings' weighted mean and its 95 % band.</p>",
      escape(on_top_of_config(f.config_creep)));
  html += "<p><b>" + escape(verdict_text(f)) + "</b></p>";
  if (f.agreement) {
    html += "<pre>" + escape(agreement_text(*f.agreement, f.recordings)) + "</pre>";
  }
  if (!f.advice.empty()) html += "<pre>" + escape(f.advice) + "</pre>";
  if (const std::string note = cells_at_zero_note(f.recordings); !note.empty()) {
    html += "<p>" + escape(note) + "</p>";
  }
  html += forest_panel(f, "gain", &MeasuredCreep::gain, &MeasuredCreep::gain_se);
  html += forest_panel(f, "tau (s)", &MeasuredCreep::tau_s, &MeasuredCreep::tau_se_s);
  html +=
      "<table><tr><th>recording</th><th>steps</th><th>gain</th><th>tau (s)</th><th>zero channel "
      "held-out NRMSE %, without and with the creep</th><th>shows it</th><th>loaded cells at 0 "
      "in the swing %</th></tr>";
  for (const RecordingCreep& r : f.recordings) {
    html += fmt::format(
        "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{:.3f} &rarr; {:.3f}</td><td>{}</td>"
        "<td>{:.0f}</td></tr>",
        escape(r.session.string()), r.steps,
        estimate_text(r.creep.gain, r.creep.gain_se, " &plusmn; "),
        estimate_text(r.creep.tau_s, r.creep.tau_se_s, " &plusmn; "), r.zero_before_pct,
        r.zero_after_pct, r.shown ? "yes" : "no", r.cells_at_zero_pct);
  }
  return html + "</table></body></html>\n";
}

}  // namespace gaitmon::cli
