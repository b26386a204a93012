// The discrepancy report: heat maps of the residual (region x stance phase) against the noise
// floor before and after the named effects, the candidates, and held-out NRMSE per region and
// per step. One HTML document, no script, no network.
#include "discrepancy_report.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <string>

#include "commands.hpp"
#include "html.hpp"

namespace gaitmon::cli {
namespace {

// Residual RMS / noise floor: 1 (white) is noise, 3 and above is saturated red.
std::string ratio_colour(double ratio) {
  const double x = std::clamp((ratio - 1.0) / 2.0, 0.0, 1.0);
  const int g = static_cast<int>(std::lround(255 - 200 * x));
  const int b = static_cast<int>(std::lround(255 - 220 * x));
  return fmt::format("rgb(255,{},{})", g, b);
}

std::string heat_map(const ResidualMap& map, const std::string& title) {
  constexpr int kLabel = 140, kCell = 44, kRow = 26, kTop = 30;
  const int width = kLabel + kCell * map.bins + 10;
  const int height = kTop + kRow * static_cast<int>(kRegionCount) + 30;
  std::string s =
      fmt::format(R"(<svg xmlns="http://www.w3.org/2000/svg" width="{}" height="{}" role="img">)"
                  R"(<text x="4" y="18" font-weight="bold">{}</text>)",
                  width, height, escape(title));
  for (const ResidualCell& c : map.cells) {
    const int x = kLabel + kCell * c.bin;
    const int y = kTop + kRow * static_cast<int>(index_of(c.region));
    const double ratio = c.noise_floor_n > 0 ? c.rms_n / c.noise_floor_n : 0.0;
    const std::string fill = c.samples > 0 ? ratio_colour(ratio) : "#eee";
    fmt::format_to(std::back_inserter(s),
                   R"(<rect x="{}" y="{}" width="{}" height="{}" fill="{}" stroke="#fff"/>)", x, y,
                   kCell, kRow, fill);
    if (c.samples > 0) {
      fmt::format_to(std::back_inserter(s),
                     R"(<text x="{}" y="{}" font-size="10" text-anchor="middle">{:.1f}</text>)",
                     x + kCell / 2, y + 17, ratio);
    }
  }
  for (Region r : kRegions) {
    fmt::format_to(std::back_inserter(s), R"(<text x="4" y="{}" font-size="12">{}</text>)",
                   kTop + kRow * static_cast<int>(index_of(r)) + 17, region_name(r));
  }
  for (int b = 0; b <= map.bins; b += 2) {
    fmt::format_to(std::back_inserter(s),
                   R"(<text x="{}" y="{}" font-size="10" text-anchor="middle">{:.1f}</text>)",
                   kLabel + kCell * b, height - 12, static_cast<double>(b) / map.bins);
  }
  s += "</svg>";
  return s;
}

// Horizontal paired bars: before (grey) and after (blue) per label.
std::string paired_bars(const std::vector<std::string>& labels, const std::vector<double>& before,
                        const std::vector<double>& after, const std::string& unit) {
  constexpr int kLabel = 150, kBar = 10, kGap = 8, kWidth = 420;
  double top = 1e-9;
  for (double v : before) top = std::max(top, v);
  for (double v : after) top = std::max(top, v);
  const int height = static_cast<int>(labels.size()) * (2 * kBar + kGap) + 20;
  std::string s =
      fmt::format(R"(<svg xmlns="http://www.w3.org/2000/svg" width="{}" height="{}" role="img">)",
                  kLabel + kWidth + 80, height);
  for (std::size_t i = 0; i < labels.size(); ++i) {
    const int y = static_cast<int>(i) * (2 * kBar + kGap) + 4;
    const auto w = [&](double v) { return static_cast<int>(std::lround(kWidth * v / top)); };
    fmt::format_to(std::back_inserter(s),
                   R"(<text x="4" y="{}" font-size="12">{}</text>)"
                   R"(<rect x="{}" y="{}" width="{}" height="{}" fill="#999"/>)"
                   R"(<text x="{}" y="{}" font-size="10">{:.2f}{}</text>)",
                   y + 2 * kBar - 2, escape(labels[i]), kLabel, y, w(before[i]), kBar,
                   kLabel + w(before[i]) + 4, y + kBar - 1, before[i], unit);
    if (i < after.size()) {
      fmt::format_to(std::back_inserter(s),
                     R"(<rect x="{}" y="{}" width="{}" height="{}" fill="#2b6cb0"/>)"
                     R"(<text x="{}" y="{}" font-size="10">{:.2f}{}</text>)",
                     kLabel, y + kBar, w(after[i]), kBar, kLabel + w(after[i]) + 4,
                     y + 2 * kBar - 1, after[i], unit);
    }
  }
  s += "</svg>";
  return s;
}

std::string step_plot(const std::vector<StepComparison>& steps) {
  constexpr int kW = 640, kH = 200, kPad = 40;
  double top = 1e-9;
  // NaN: a step found in only one of two readings (find_discrepancy_undoing_creep).
  for (const auto& s : steps) {
    for (double v : {s.baseline_nrmse_pct, s.extended_nrmse_pct}) {
      if (std::isfinite(v)) top = std::max(top, v);
    }
  }
  const auto line = [&](bool extended, const char* colour) {
    std::string pts;
    for (std::size_t i = 0; i < steps.size(); ++i) {
      const double v = extended ? steps[i].extended_nrmse_pct : steps[i].baseline_nrmse_pct;
      if (!std::isfinite(v)) continue;
      const double x =
          kPad + (kW - 2 * kPad) * (steps.size() > 1 ? double(i) / (steps.size() - 1) : 0.5);
      const double y = kH - kPad + 10 - (kH - kPad) * v / top;
      pts += fmt::format("{:.1f},{:.1f} ", x, y);
    }
    return fmt::format(R"(<polyline fill="none" stroke="{}" stroke-width="1.5" points="{}"/>)",
                       colour, pts);
  };
  return fmt::format(
      R"(<svg xmlns="http://www.w3.org/2000/svg" width="{}" height="{}" role="img">)"
      R"(<line x1="{}" y1="{}" x2="{}" y2="{}" stroke="#000"/>{}{})"
      R"(<text x="4" y="14" font-size="11">{:.1f} %</text>)"
      R"(<text x="{}" y="{}" font-size="11" text-anchor="middle">steps in time order</text>)"
      R"(</svg>)",
      kW, kH + 10, kPad, kH - kPad + 10, kW - kPad, kH - kPad + 10, line(false, "#999"),
      line(true, "#2b6cb0"), top, kW / 2, kH + 4);
}

// Each foot's zero (summed bits) against its steps' heel strike times: a drift, from creep or a
// warming insole, is a rising line; without one the line stays flat within its scatter.
std::string zero_level_plot(const std::vector<ZeroLevelDrift>& levels) {
  constexpr int kW = 640, kH = 200, kPad = 50;
  double t0 = 0, t1 = 0, lo = 0, hi = 0;
  bool any = false;
  for (const ZeroLevelDrift& z : levels) {
    for (std::size_t i = 0; i < z.t_s.size() && i < z.zero_bits.size(); ++i) {
      if (!any) {
        t0 = t1 = z.t_s[i];
        lo = hi = z.zero_bits[i];
        any = true;
      }
      t0 = std::min(t0, z.t_s[i]);
      t1 = std::max(t1, z.t_s[i]);
      lo = std::min(lo, z.zero_bits[i]);
      hi = std::max(hi, z.zero_bits[i]);
    }
  }
  if (!any) return "";
  if (!(t1 > t0)) t1 = t0 + 1.0;
  if (!(hi > lo)) hi = lo + 1.0;
  const int bottom = kH - 30;
  std::string lines, legend;
  int row = 0;
  for (const ZeroLevelDrift& z : levels) {
    const char* colour = z.foot == Foot::Left ? "#2b6cb0" : "#c05621";
    std::string pts;
    for (std::size_t i = 0; i < z.t_s.size() && i < z.zero_bits.size(); ++i) {
      const double x = kPad + (kW - 2 * kPad) * (z.t_s[i] - t0) / (t1 - t0);
      const double y = bottom - (bottom - 10) * (z.zero_bits[i] - lo) / (hi - lo);
      pts += fmt::format("{:.1f},{:.1f} ", x, y);
    }
    lines += fmt::format(R"(<polyline fill="none" stroke="{}" stroke-width="1.5" points="{}"/>)",
                         colour, pts);
    legend += fmt::format(R"(<text x="{}" y="{}" font-size="11" fill="{}">foot {}</text>)",
                          kW - kPad + 4, 20 + 14 * row++, colour, foot_name(z.foot));
  }
  return fmt::format(
      R"(<svg xmlns="http://www.w3.org/2000/svg" width="{}" height="{}" role="img">)"
      R"(<line x1="{}" y1="{}" x2="{}" y2="{}" stroke="#000"/>)"
      R"(<line x1="{}" y1="10" x2="{}" y2="{}" stroke="#000"/>{}{})"
      R"(<text x="{}" y="14" font-size="11" text-anchor="end">{:.0f}</text>)"
      R"(<text x="{}" y="{}" font-size="11" text-anchor="end">{:.0f}</text>)"
      R"(<text x="4" y="{}" font-size="11">bits</text>)"
      R"(<text x="{}" y="{}" font-size="11" text-anchor="middle">{:.0f} s</text>)"
      R"(<text x="{}" y="{}" font-size="11" text-anchor="middle">{:.0f} s</text>)"
      R"(<text x="{}" y="{}" font-size="11" text-anchor="middle">heel strike time</text>)"
      R"(</svg>)",
      kW, kH, kPad, bottom, kW - kPad, bottom, kPad, kPad, bottom, lines, legend, kPad - 4, hi,
      kPad - 4, bottom, lo, kH / 2, kPad, bottom + 14, t0, kW - kPad, bottom + 14, t1, kW / 2,
      bottom + 26);
}

}  // namespace

std::string render_discrepancy_html(const std::string& session_name, const DiscrepancyResult& r) {
  std::string named;
  for (const EffectEstimate& e : r.named_effects) {
    named += "<li><b>" + escape(e.name) + "</b>: ";
    for (const ParamEstimate& p : e.params) {
      named += fmt::format("{} = {}; ", escape(p.name), param_text(p, " &plusmn; "));
    }
    named += "</li>";
  }
  if (named.empty()) named = "<li>none</li>";
  if (!r.not_named_reason.empty()) {
    named += fmt::format("<li>the most likely candidate, {}, is not named: {}</li>",
                         escape(r.most_likely_candidate), escape(r.not_named_reason));
  }

  std::string candidates =
      "<table><tr><th>candidate</th><th>held-out NRMSE %</th><th>shrink %</th><th>in-sample "
      "NRMSE %</th><th>zero channel shrink %</th><th>&Delta;BIC</th><th>parameters</th></tr>";
  const auto rows = [&](const std::vector<CandidateResult>& list) {
    for (const CandidateResult& c : list) {
      std::string params;
      for (const ParamEstimate& p : c.params) {
        params += fmt::format("{} = {}<br>", escape(p.name), param_text(p, " &plusmn; "));
      }
      candidates += fmt::format(
          "<tr><td>{}</td><td>{:.2f}</td><td>{:.1f}</td><td>{:.2f}</td><td>{:.1f}</td><td>{:.0f}"
          "</td><td>{}</td></tr>",
          escape(c.name), c.heldout_nrmse_pct, c.shrink_pct, c.in_sample_nrmse_pct,
          c.zero_shrink_pct, c.delta_bic, params);
    }
  };
  rows(r.candidates);
  candidates += "</table>";
  std::string seconds;
  if (!r.second_candidates.empty()) {
    candidates += fmt::format(
        "<h3>{}</h3><table><tr><th>candidate</th>"
        "<th>held-out NRMSE %</th><th>shrink %</th><th>in-sample NRMSE %</th>"
        "<th>zero channel shrink %</th><th>&Delta;BIC</th><th>parameters</th></tr>",
        r.creep_undone
            ? fmt::format("On the readings with the sensor creep undone ({} steps; the baseline's "
                          "held-out NRMSE {:.2f} % there, {:.2f} % as read)",
                          r.creep_undone->steps, r.creep_undone->baseline_heldout_nrmse_pct,
                          r.baseline_heldout_nrmse_pct)
            : std::string("On top of the first named effect"));
    rows(r.second_candidates);
    candidates += "</table>";
  }

  std::vector<std::string> labels{"overall"};
  std::vector<double> before{r.baseline_heldout_nrmse_pct}, after{r.extended_heldout_nrmse_pct};
  for (const RegionComparison& c : r.regions) {
    if (c.step_regions == 0) continue;
    labels.emplace_back(region_name(c.region));
    before.push_back(c.baseline_heldout_nrmse_pct);
    after.push_back(c.extended_heldout_nrmse_pct);
  }
  std::vector<std::string> cand_labels;
  std::vector<double> cand_values;
  for (const CandidateResult& c : r.candidates) {
    cand_labels.push_back(c.name);
    cand_values.push_back(c.heldout_nrmse_pct);
  }
  cand_labels.insert(cand_labels.begin(), "baseline");
  cand_values.insert(cand_values.begin(), r.baseline_heldout_nrmse_pct);

  std::string where =
      "<table><tr><th>region</th><th>phase</th><th>samples</th><th>residual RMS "
      "N</th><th>bias N</th><th>noise floor N</th></tr>";
  for (const ResidualCell& c : r.where) {
    where += fmt::format(
        "<tr><td>{}</td><td>{:.1f}-{:.1f}</td><td>{}</td><td>{:.2f}</td><td>{:+.2f}</td><td>{:.2f}"
        "</td></tr>",
        region_name(c.region), static_cast<double>(c.bin) / r.map_before.bins,
        static_cast<double>(c.bin + 1) / r.map_before.bins, c.samples, c.rms_n, c.bias_n,
        c.noise_floor_n);
  }
  where += "</table>";
  if (r.where.empty()) {
    where = "<p>No region and phase has a residual above its noise floor.</p>";
  }

  std::string diag = "<table><tr><th>state</th><th>correlation with residual</th></tr>";
  for (const StateCorrelation& c : r.diagnostics.correlations) {
    diag += fmt::format("<tr><td>{}</td><td>{:+.3f}</td></tr>", escape(c.state), c.r);
  }
  diag += "</table>";
  std::string bias;
  for (double b : r.diagnostics.bias_per_phase_pct) bias += fmt::format("{:+.2f} ", b);

  std::string html = page_head("gaitmon discrepancy: " + session_name);
  html += "<h1>Model-data discrepancy: " + escape(session_name) + "</h1>";
  html += fmt::format(
      "<p>{} steps, {} step-regions, {} frames ({} step-regions left out: their cells give no "
      "footprint, and their contact ellipse moves in whole cells). Pooled NRMSE (eq 58, regions "
      "weighted by their force; 1 % is {:.2f} N RMS). Noise floor {:.2f} %.</p>",
      r.steps, r.step_regions, r.frames, r.step_regions_left_out, r.nrmse_scale_n / 100.0,
      r.noise_floor_nrmse_pct);
  if (r.ceiling_plateau_steps >= 0) {
    html += fmt::format(
        "<p>A ceiling in the readings: {} of {} steps have a frame in which two or more cells of "
        "one region read at the session's top (sensor_saturation is named only where enough "
        "do).</p>",
        r.ceiling_plateau_steps, r.steps);
  }
  if (r.neighbour_share.cell_frames > 0) {
    html += fmt::format(
        "<p>Crosstalk in the readings: 1 % of the cells next to loaded ones read under {:.3f} of "
        "their neighbours' readings (a cell wholly outside a contact reads nothing without "
        "crosstalk; crosstalk is named only where this share shows).</p>",
        r.neighbour_share.floor);
  }
  if (r.cell_coupling.frames > 0) {
    html += fmt::format(
        "<p>Crosstalk in the cells: their readings fit their caps best with a coupling of {:.3f} "
        "undone (crosstalk is named only where this shows too: cells that average the pressure "
        "raise the share above by their partly covered rim, and not this).</p>",
        r.cell_coupling.coupling);
  }
  html += "<h2>Named effects</h2><ul>" + named + "</ul>";
  html += fmt::format(
      "<p>Held-out NRMSE {:.2f} % &rarr; {:.2f} %: the gap shrinks by <b>{:.1f} %</b>.{}</p>",
      r.baseline_heldout_nrmse_pct, r.extended_heldout_nrmse_pct, r.gap_shrink_pct,
      r.creep_undone ? " The zeros name a sensor creep: every figure after is of the session "
                       "read again with it undone in every frame (a step found in only one of the "
                       "two readings has none), each step-region against its own peak there."
                     : "");
  if (r.zero_changes > 0) {
    html += fmt::format(
        "<p>Zero channel ({} step-to-step changes of the step-regions' zeros, which the model "
        "without a creeping or drifting sensor expects to be 0): held-out NRMSE {:.3f} % &rarr; "
        "{:.3f} %, "
        "the gap shrinks by <b>{:.1f} %</b>.</p>",
        r.zero_changes, r.zero_baseline_heldout_nrmse_pct, r.zero_extended_heldout_nrmse_pct,
        r.zero_gap_shrink_pct);
    html += paired_bars({"zero changes"}, {r.zero_baseline_heldout_nrmse_pct},
                        {r.zero_extended_heldout_nrmse_pct}, " %");
  }
  html += "<h2>Held-out NRMSE before (grey) and after (blue)</h2>" +
          paired_bars(labels, before, after, " %");
  html +=
      "<h2>Residual maps</h2><p>Residual RMS / noise floor per region and normalised stance "
      "time (heel strike 0, toe off 1); 1 is noise, 3 or more is deep red.</p>";
  html += heat_map(r.map_before, "Before (baseline model)");
  html +=
      heat_map(r.map_after, r.creep_undone
                                ? "After (with the named effects, the creep undone in the readings)"
                                : "After (with the named effects)");
  html += "<h2>Where: the cells furthest above the noise floor</h2>" + where;
  html += "<h2>Candidates (each on top of the baseline)</h2>" +
          paired_bars(cand_labels, cand_values, {}, " %") + candidates;
  html += "<h2>Per step (held-out)</h2>" + step_plot(r.per_step);
  html += fmt::format(
      "<h2>Residual diagnostics (baseline)</h2><p>Lag-1 autocorrelation {:.3f}; runs test z "
      "{:.1f}; effective sample fraction {:.3f}.</p><p>Bias per phase bin, % of peak force: {}</p>",
      r.diagnostics.lag1_autocorrelation, r.diagnostics.runs_z,
      r.diagnostics.effective_sample_fraction, bias);
  html += diag;
  html += fmt::format(
      "<h2>Zero level per foot</h2><p>Each step is zeroed at the swings around it (seed 3.3.1), "
      "which takes a slow drift of the readings out of the force; a sensor that creeps under "
      "load, or a thermal drift, shows here instead. Drifting: the range is over {:g} "
      "step-to-step scatters (at least 1 bit) and at least {:g} % of the peak.</p><table><tr>"
      "<th>foot</th><th>steps</th><th>first bits</th><th>last bits</th><th>lowest</th>"
      "<th>highest</th><th>scatter bits</th><th>range % of peak</th><th>drifting</th></tr>",
      kZeroDriftScatters, kZeroDriftPctOfPeak);
  for (const ZeroLevelDrift& z : r.zero_levels) {
    html += fmt::format(
        "<tr><td>{}</td><td>{}</td><td>{:.1f}</td><td>{:.1f}</td><td>{:.1f}</td><td>{:.1f}</td>"
        "<td>{:.1f}</td><td>{:.2f}</td><td>{}</td></tr>",
        foot_name(z.foot), z.steps, z.first_bits, z.last_bits, z.lowest_bits, z.highest_bits,
        z.scatter_bits, z.range_pct_of_peak, z.drifting ? "<b>yes</b>" : "no");
  }
  html += "</table>" + zero_level_plot(r.zero_levels) + "</body></html>\n";
  return html;
}

}  // namespace gaitmon::cli
