// The analyze report drawn from analyses made by hand: the summary, the parameter table beside
// Appendix I, the effects' parameters with both errors, the regions nothing was fitted in, the
// step table, links, escaping and no nan.
#include "src/cli/report_html.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "test_support.hpp"

namespace gaitmon::cli {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Five frames at 100 Hz from heel strike; only the heel is loaded, and fitted with `nrmse_pct`.
StepAnalysis heel_step(Foot foot, int step, double t_heel_strike_s, double nrmse_pct) {
  StepAnalysis s;
  s.foot = foot;
  s.step = step;
  s.t_heel_strike_s = t_heel_strike_s;
  s.t_toe_off_s = t_heel_strike_s + 0.04;
  for (int i = 0; i < 5; ++i) s.t_s.push_back(t_heel_strike_s + 0.01 * i);
  for (std::size_t i = 0; i < kRegionCount; ++i) s.regions[i].region = kRegions[i];
  RegionAnalysis& heel = s.regions[index_of(Region::Heel)];
  heel.series = {s.t_s, {0.0, 900.0, 1800.0, 900.0, 0.0}, {0.0, 150.0, 300.0, 150.0, 0.0}};
  heel.fit.status = FitStatus::Ok;
  heel.fit.nrmse_pct = nrmse_pct;
  heel.fit.model_force_n = {0.0, 140.0, 310.0, 150.0, 0.0};
  heel.fit.kbar_n_per_mm3 = {.value = 0.1 + 0.01 * step, .se = 0.01, .free = true};
  heel.fit.n = {.value = 0.3, .se = 0.05, .free = true};
  heel.fit.cbar_ns_per_mm3 = {.value = 0.011, .se = 0.002, .free = true};
  heel.fit.m = {.value = 1.2, .se = 0.1, .free = true};
  return s;
}

struct Fixture {
  Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  AnalysisSettings settings;
  std::vector<StepRow> rows;
  std::vector<StepAnalysis> analyses;
  SessionAnalysis session;

  Fixture() {
    rows = {{Foot::Left, 0, 0.1, 0.7, 650.0, StepStatus::Ok, 2.0},
            {Foot::Right, 1, 0.6, 1.2, 640.0, StepStatus::Ok, 3.0},
            {Foot::Left, 2, 1.1, 1.7, 655.5, StepStatus::Ok, 2.5},
            {Foot::Right, 3, 1.6, 1.9, 120.0, StepStatus::Incomplete, std::nullopt},
            {Foot::Left, 4, 2.1, 2.7, 600.0, StepStatus::Ok, 9.0}};
    analyses = {heel_step(Foot::Left, 0, 0.1, 1.0), heel_step(Foot::Right, 1, 0.6, 5.0),
                heel_step(Foot::Left, 2, 1.1, 3.0), heel_step(Foot::Left, 4, 2.1, 50.0)};
    // A step whose heel fit failed: in no chart, whatever its numbers say.
    analyses.back().regions[index_of(Region::Heel)].fit.status = FitStatus::Failed;
    session.nrmse_total_pct = {.count = 3, .median = 2.5, .q1 = 2.0, .q3 = 3.0};
    for (std::size_t i = 0; i < kRegionCount; ++i) session.regions[i].region = kRegions[i];

    RegionSessionAnalysis& heel = session.regions[index_of(Region::Heel)];
    heel.steps_with_contact = 3;
    heel.steps_fitted = 3;
    heel.aspect = 0.95;
    heel.session_fit.status = FitStatus::Ok;
    heel.session_fit.nrmse_pct = 4.3;
    heel.session_fit.C_mm = {.value = 69.9, .free = false};
    heel.session_fit.kbar_n_per_mm3 = {.value = 0.12, .se = 0.01, .free = true};
    heel.session_fit.n = {.value = 0.3, .se = kInf, .free = true};
    heel.session_fit.cbar_ns_per_mm3 = {
        .value = 0.011, .se = 0.002, .at_bound = true, .free = true};
    heel.pooling.pooled = true;
    heel.pooling.mean = {std::log(0.12), 0.3, std::log(0.011), 1.2};
    heel.pooling.between_step[0][0] = 0.01;    // 10 % on kbar, pooled as a logarithm
    heel.pooling.between_step[1][1] = 0.0004;  // 0.02 on n
    heel.pooling.between_step[2][2] = 0.04;    // 20 % on cbar, a logarithm too
    // The mean's SEs with the chain's error: 5 % on kbar, 0.01 on n, 10 % on cbar, 0.02 on m.
    heel.pooled_mean = MaterialEstimate{heel.pooling.mean, {}, std::nullopt};
    heel.pooled_mean->covariance[0][0] = 0.0025;
    heel.pooled_mean->covariance[1][1] = 0.0001;
    heel.pooled_mean->covariance[2][2] = 0.01;
    heel.pooled_mean->covariance[3][3] = 0.0004;
    heel.kbar_n_per_mm3 = {.count = 3, .median = 0.12, .q1 = 0.11, .q3 = 0.13};
    heel.nrmse_pct = {.count = 3, .median = 3.0, .q1 = 2.0, .q3 = 4.0};

    RegionSessionAnalysis& toe2 = session.regions[index_of(Region::Toe2)];
    toe2.steps_with_contact = 2;
    toe2.steps_on_ellipse = 2;
    toe2.session_fit.status = FitStatus::Failed;
    toe2.session_fit.reason = "<2 frames";
    toe2.pooling.not_pooled = "fewer than 3 steps & no fit";
  }

  ReportInput input() const {
    return {.session_name = "walk <1>",
            .size = InsoleSize::S37_38,
            .sample_rate_hz = 100.0,
            .config = &config,
            .settings = &settings,
            .steps = rows,
            .analyses = analyses,
            .session = &session};
  }
};

using test::count;

bool has(const std::string& html, std::string_view what) {
  return html.find(what) != std::string::npos;
}

TEST(ReportHtml, SummarisesTheSessionAndItsSettings) {
  const Fixture f;
  const std::string html = render_report_html(f.input());
  EXPECT_TRUE(has(html, "<title>gaitmon analyze: walk &lt;1&gt;</title>"));
  EXPECT_TRUE(has(html,
                  "<h1>gaitmon analyze: walk &lt;1&gt;</h1><p>Insole 37-38, 100 Hz; 5 "
                  "steps, 4 complete and analysed. Model correct, fit identifiable, "
                  "smoothing none, contact area footprint. Median total-force NRMSE 2.5 % "
                  "(IQR 1.0 %).</p>"));
  EXPECT_TRUE(has(html, "C and d0 are <b>declared</b>, not fitted"));
  EXPECT_TRUE(has(html, "with P = &pi;AB from Appendix I."));
  EXPECT_FALSE(has(html, "<b>--fit seed8</b>"));
  Fixture automatic;
  ReportInput auto_input = automatic.input();
  auto_input.area_auto = true;
  EXPECT_TRUE(has(render_report_html(auto_input),
                  "smoothing none, contact area footprint (auto, from how the cells read). "
                  "Median"));

  // With --free-scale the note had still said that P comes from Appendix I.
  Fixture free_scale;
  free_scale.settings.fit.free_scale = true;
  const std::string scaled = render_report_html(free_scale.input());
  EXPECT_TRUE(has(scaled, "with P = &pi;AB fitted per region-step (--free-scale)."));
  EXPECT_FALSE(has(scaled, "from Appendix I."));

  Fixture seed8;
  seed8.settings.fit.mode = FitMode::Seed8;
  seed8.settings.fit.free_scale = true;
  seed8.settings.fit.end_rate = EndRate::SecondOrder;
  const std::string other = render_report_html(seed8.input());
  EXPECT_TRUE(has(other,
                  "fit seed8, smoothing none, contact area footprint, second-order area "
                  "rate at contact ends, P free."));
  EXPECT_TRUE(has(other, "<b>--fit seed8</b>: all eight parameters are free"));
  EXPECT_FALSE(has(other, "C and d0 are <b>declared</b>"));
}

// Each effect's parameter with both its errors: the curvature's, and the step-clustered
// sandwich's where there is one; none where the data do not determine the parameter.
TEST(ReportHtml, TablesTheEffectsParametersWithBothErrors) {
  const Fixture f;
  ExtendedModelFit fit;
  fit.effects = {
      {"stress_relaxation",
       {{"strength", 0.3, 0.01, 0.025},
        {"tau_s", 0.2, 0.02, std::numeric_limits<double>::quiet_NaN()}}},
      {"hysteresis", {{"strength", 0.0, std::numeric_limits<double>::quiet_NaN(), 0.5}}}};
  ReportInput input = f.input();
  input.extended = &fit;
  const std::string html = render_report_html(input);
  EXPECT_TRUE(has(html, "<th>value (SE)</th><th>step-clustered sandwich SE</th>"));
  EXPECT_TRUE(has(html,
                  "<tr><td>stress_relaxation</td><td>strength</td><td>0.3 (0.01)</td>"
                  "<td>0.025</td><td>inside</td></tr>"));
  EXPECT_TRUE(has(html,
                  "<tr><td>stress_relaxation</td><td>tau_s</td><td>0.2 (0.02)</td>"
                  "<td>&ndash;</td><td>inside</td></tr>"));
  EXPECT_TRUE(has(html,
                  "<tr><td>hysteresis</td><td>strength</td><td>0 (undetermined)</td>"
                  "<td>&ndash;</td><td>inside</td></tr>"));
}

TEST(ReportHtml, TablesEachParameterBesideAppendixI) {
  const Fixture f;
  const std::string html = render_report_html(f.input());
  // Appendix I, size 37-38, heel: kbar 0.117 (0.027), C 69.9 (8.5), n 0.294 (0.116),
  // cbar 0.011 (0.001), NRMSE 25.5 (4.2).
  EXPECT_TRUE(has(html,
                  "<tr><td>kbar (N/mm\u00b3)</td><td>0.12 (0.01)</td><td>0.12 (0.02)</td>"
                  "<td>0.12 &plusmn; 0.006 (10 %)</td><td>0.117 (0.027)</td></tr>"));
  EXPECT_TRUE(has(html,
                  "<tr><td>n</td><td>0.3 (undetermined)</td><td>&ndash;</td>"
                  "<td>0.3 &plusmn; 0.01 (0.02)</td><td>0.294 (0.116)</td></tr>"));
  EXPECT_TRUE(has(html,
                  "<tr><td>C (mm)</td><td>69.9 <i>declared</i></td><td>&ndash;</td>"
                  "<td>&ndash;</td><td>69.9 (8.5)</td></tr>"));
  EXPECT_TRUE(has(html,
                  "<td>0.011 (0.002) <b>at bound</b></td><td>&ndash;</td>"
                  "<td>0.011 &plusmn; 0.0011 (20 %)</td><td>0.011 (0.001)</td></tr>"));
  EXPECT_TRUE(has(html,
                  "<tr><td>NRMSE (%)</td><td>4.3</td><td>3.0 (2.0)</td><td>&ndash;</td>"
                  "<td>25.5 (4.2)</td></tr>"));
  EXPECT_TRUE(has(html,
                  "<p>3 steps with contact, 3 fitted; session-level fit: ok. A/B = 0.950 "
                  "(median measured contact-ellipse aspect).</p>"));
}

TEST(ReportHtml, DrawsTheTypicalStepAndAllStepsOfAFittedRegion) {
  const Fixture f;
  const std::string html = render_report_html(f.input());
  // NRMSE 1, 5 and 3 %: the median is the left foot's step 2.
  EXPECT_TRUE(has(html, ">typical step (L 2, NRMSE 3.0 %)</text>"));
  EXPECT_TRUE(has(html, ">all steps (3 of 3 shown)</text>"));
  EXPECT_TRUE(has(html, ">contact area given to the fit</text>"));
  EXPECT_TRUE(has(html, ">kbar over the session</text>"));
  EXPECT_TRUE(has(html, ">cbar over the session</text>"));
  // Three per-step charts of the heel's (force, model, area), four strips and two courses over
  // the session, on the heel alone.
  EXPECT_EQ(count(html, "<svg "), 9u);
  // A dot per step fitted in each strip and each course: the failed fit has none.
  EXPECT_EQ(count(html, "<circle "), 6u * 3u);
}

/// The `<svg>` elements of the page, in order.
std::vector<std::string> charts(const std::string& html) {
  std::vector<std::string> out;
  for (auto at = html.find("<svg "); at != std::string::npos; at = html.find("<svg ", at + 1)) {
    out.push_back(html.substr(at, html.find("</svg>", at) - at));
  }
  return out;
}

/// (cx, fill) of every circle of one chart, in the order drawn.
std::vector<std::pair<double, std::string>> dots(const std::string& svg) {
  std::vector<std::pair<double, std::string>> out;
  for (auto at = svg.find("<circle cx=\""); at != std::string::npos;
       at = svg.find("<circle cx=\"", at + 1)) {
    const auto fill = svg.find("fill=\"", at) + 6;
    out.emplace_back(std::stod(svg.substr(at + 12)), svg.substr(fill, svg.find('"', fill) - fill));
  }
  return out;
}

/// The points of the first line drawn in `colour`, in pixels; none if there is no such line.
std::vector<std::pair<double, double>> polyline_points(const std::string& svg,
                                                       const std::string& colour) {
  const auto line = svg.find("<polyline fill=\"none\" stroke=\"" + colour + "\"");
  if (line == std::string::npos) return {};
  const auto points = svg.find("points=\"", line) + 8;
  std::istringstream xy(svg.substr(points, svg.find('"', points) - points));
  std::vector<std::pair<double, double>> out;
  double x, y;
  char comma;
  while (xy >> x >> comma >> y) out.emplace_back(x, y);
  return out;
}

/// The top and bottom of a chart's plot frame, in pixels.
std::pair<double, double> frame_span(const std::string& svg) {
  const auto frame = svg.rfind("<rect ", svg.find("class=\"frame\""));
  const auto y = svg.find("y=\"", frame) + 3;
  const auto height = svg.find("height=\"", frame) + 8;
  const double top = std::stod(svg.substr(y));
  return {top, top + std::stod(svg.substr(height))};
}

/// The points of every band drawn in `colour`, in pixels, in the order drawn.
std::vector<std::vector<std::pair<double, double>>> band_points(const std::string& svg,
                                                                const std::string& colour) {
  std::vector<std::vector<std::pair<double, double>>> out;
  const std::string tag = "<polygon class=\"band\" fill=\"" + colour + "\"";
  for (auto at = svg.find(tag); at != std::string::npos; at = svg.find(tag, at + 1)) {
    const auto points = svg.find("points=\"", at) + 8;
    std::istringstream xy(svg.substr(points, svg.find('"', points) - points));
    auto& band = out.emplace_back();
    double x, y;
    char comma;
    while (xy >> x >> comma >> y) band.emplace_back(x, y);
  }
  return out;
}

// kbar over the session: a dot per fitted step at its heel strike, blue for the left foot and
// green for the right, and where the steps were pooled a line per foot through their pooled
// values in a band of one standard error either side, cut at the plot's edges; nothing for the
// step whose fit failed.
TEST(ReportHtml, DrawsEachStepsStiffnessAgainstItsHeelStrikePerFoot) {
  Fixture f;
  RegionSessionAnalysis& heel = f.session.regions[index_of(Region::Heel)];
  heel.pooled_per_step.resize(f.analyses.size());
  for (std::size_t i = 0; i + 1 < f.analyses.size(); ++i) {
    MaterialParams p;
    p.kbar_n_per_mm3.value = 0.115;
    // The left foot's steps are 0 and 1 of the analyses, the right one's 2 (below).
    p.kbar_n_per_mm3.se = i < 2 ? 0.002 : 10.0;
    heel.pooled_per_step[i] = p;
  }
  const std::vector<std::string> svgs = charts(render_report_html(f.input()));
  ASSERT_EQ(svgs.size(), 9u);
  const std::string& kbar = svgs[7];
  ASSERT_TRUE(has(kbar, ">kbar over the session</text>"));
  const auto d = dots(kbar);
  // The analyses are by foot: L 0 (0.1 s), L 2 (1.1 s), R 1 (0.6 s); L 4 failed.
  ASSERT_EQ(d.size(), 3u);
  EXPECT_EQ(d[0].second, "#1f77b4");
  EXPECT_EQ(d[1].second, "#1f77b4");
  EXPECT_EQ(d[2].second, "#2ca02c");
  EXPECT_LT(d[0].first, d[2].first);
  EXPECT_LT(d[2].first, d[1].first);
  // Each foot's pooled line, the left one through two steps at one value: level.
  EXPECT_EQ(count(kbar, "<polyline "), 2u);
  const auto left = polyline_points(kbar, "#1f77b4");
  ASSERT_EQ(left.size(), 2u) << kbar;
  EXPECT_LT(left[0].first, left[1].first);
  EXPECT_DOUBLE_EQ(left[0].second, left[1].second);
  EXPECT_TRUE(has(kbar, ">pooled \u00b1 SE (lines)</text>"));
  // The left band: along the line's two steps at the SE below, then back at the SE above, as
  // far from the line on either side.
  const auto left_bands = band_points(kbar, "#1f77b4");
  ASSERT_EQ(left_bands.size(), 1u) << kbar;
  const auto& band = left_bands[0];
  ASSERT_EQ(band.size(), 4u) << kbar;
  EXPECT_EQ(band[0].first, left[0].first);
  EXPECT_EQ(band[1].first, left[1].first);
  EXPECT_EQ(band[2].first, left[1].first);
  EXPECT_EQ(band[3].first, left[0].first);
  EXPECT_GT(band[0].second, left[0].second + 1.0) << "below the line: further down the chart";
  EXPECT_NEAR(band[0].second - left[0].second, left[0].second - band[3].second, 0.11);
  // The right foot's SE of 10 would span the chart a hundred times over: cut at its frame, the
  // scale set by the values.
  const auto right_bands = band_points(kbar, "#2ca02c");
  ASSERT_EQ(right_bands.size(), 1u) << kbar;
  const auto [frame_top, frame_bottom] = frame_span(kbar);
  for (const auto& [x, y] : right_bands[0]) {
    EXPECT_GE(y, frame_top - 0.05) << kbar;
    EXPECT_LE(y, frame_bottom + 0.05) << kbar;
  }

  const std::vector<std::string> unpooled = charts(render_report_html(Fixture().input()));
  ASSERT_EQ(unpooled.size(), 9u);
  EXPECT_EQ(count(unpooled[7], "<polyline "), 0u);
  EXPECT_EQ(count(unpooled[7], "<polygon "), 0u);
  EXPECT_FALSE(has(unpooled[7], ">pooled \u00b1 SE (lines)</text>"));
}

// A region's trend over the session is drawn as a line across the steps' span, falling where
// the trend falls, and its change per minute goes in the legend; without one there is no line.
TEST(ReportHtml, DrawsTheTrendOverTheSessionWhereThereIsOne) {
  Fixture f;
  LogTrend trend;
  trend.steps = 5;
  trend.centre_s = 0.6;
  trend.ln_at_centre = std::log(0.12);
  trend.ln_slope_per_min = -3.0;
  trend.pct_per_min = -5.0;
  trend.se_pct_per_min = 1.2;
  f.session.regions[index_of(Region::Heel)].kbar_trend = trend;
  const std::vector<std::string> svgs = charts(render_report_html(f.input()));
  ASSERT_EQ(svgs.size(), 9u);
  const std::string& kbar = svgs[7];
  // Two points: the first and last heel strike.
  const auto line = polyline_points(kbar, "#d62728");
  ASSERT_EQ(line.size(), 2u) << kbar;
  EXPECT_LT(line[0].first, line[1].first);
  EXPECT_LT(line[0].second, line[1].second) << "a falling trend runs down the chart";
  EXPECT_TRUE(has(kbar, ">-5.0 \u00b1 1.2 %/min</text>")) << kbar;
  EXPECT_FALSE(has(svgs[8], "stroke=\"#d62728\"")) << "the cbar chart has no trend here";
}

// The feet are compared in one chart before the regions: each region's kbar and cbar as a marker
// with a bar of two standard errors either side, above zero where the right foot's is higher, and
// in a table that bolds what reaches 3 standard errors outside the toes. Without any comparison
// there is no chart, only why.
TEST(ReportHtml, ComparesTheFeetRegionByRegion) {
  Fixture f;
  const std::string without = render_report_html(f.input());
  EXPECT_TRUE(has(without,
                  "<section id=\"feet\"><h2>Left against right</h2><p>Not compared: no "
                  "region has 3 steps of each foot"))
      << without;
  FootAsymmetry stiffer;
  stiffer.left_steps = 40;
  stiffer.right_steps = 41;
  stiffer.ln_ratio = std::log(1.1);
  stiffer.se_ln_ratio = 0.01;
  stiffer.pct = 10.0;
  stiffer.se_pct = 1.1;
  f.session.regions[index_of(Region::Heel)].kbar_asymmetry = stiffer;
  FootAsymmetry unclear = stiffer;
  unclear.ln_ratio = std::log(0.96);
  unclear.se_ln_ratio = 0.05;
  unclear.pct = -4.0;
  unclear.se_pct = 4.8;
  f.session.regions[index_of(Region::Met3_5)].cbar_asymmetry = unclear;
  f.session.regions[index_of(Region::Toe1)].kbar_asymmetry = stiffer;
  const std::string html = render_report_html(f.input());
  const auto begin = html.find("<section id=\"feet\">");
  ASSERT_NE(begin, std::string::npos);
  EXPECT_LT(begin, html.find("<section id=\"heel\">"));
  const std::string section = html.substr(begin, html.find("</section>", begin) - begin);
  const std::vector<std::string> svgs = charts(section);
  ASSERT_EQ(svgs.size(), 1u);
  EXPECT_TRUE(has(svgs[0], "Right foot against left")) << svgs[0];
  EXPECT_EQ(count(svgs[0], "width=\"8\" height=\"8\""), 3u)
      << "a marker for the heel's and toe1's kbar and met3_5's cbar";
  // The heel's marker (the first drawn) above the zero line, met3_5's (the second) below it.
  const auto zero = polyline_points(svgs[0], "#222222");
  ASSERT_EQ(zero.size(), 2u);
  std::vector<double> marker_ys;
  for (auto at = svgs[0].find("width=\"8\" height=\"8\""); at != std::string::npos;
       at = svgs[0].find("width=\"8\" height=\"8\"", at + 1)) {
    const auto y = svgs[0].rfind(" y=\"", at);
    marker_ys.push_back(std::stod(svgs[0].substr(y + 4)) + 4.0);
  }
  ASSERT_EQ(marker_ys.size(), 3u);
  EXPECT_LT(marker_ys[0], zero[0].second);
  EXPECT_GT(marker_ys[1], zero[0].second);
  EXPECT_TRUE(has(section, "<tr><td>heel</td><td><b>+10.0 &plusmn; 1.1 (z +9.5)</b></td>"))
      << section;
  EXPECT_TRUE(has(section, "<tr><td>met3_5</td><td>&ndash;</td><td>-4.0 &plusmn; 4.8 (z -0.8)"))
      << section;
  EXPECT_TRUE(has(section, "<tr><td>toe1</td><td>+10.0 &plusmn; 1.1 (z +9.5)</td>")) << section;
}

/// The x of every legend's box, in the order the charts are drawn.
std::vector<double> legend_xs(const std::string& html) {
  std::vector<double> xs;
  const std::string_view box = "class=\"legend-box\"";
  for (auto at = html.find(box); at != std::string::npos; at = html.find(box, at + 1)) {
    const auto rect = html.rfind("<rect x=\"", at);
    xs.push_back(std::stod(html.substr(rect + 9)));
  }
  return xs;
}

// A legend sits in the top corner the lines leave free: the right one where the force and area
// peak early (the heel), the left one where they peak at the end of the stance (a forefoot).
TEST(ReportHtml, PutsEachLegendInTheTopCornerTheLinesLeaveFree) {
  Fixture early;
  std::vector<double> right = legend_xs(render_report_html(early.input()));
  ASSERT_EQ(right.size(), 5u);
  right.resize(3);  // the force and area charts
  // Charts 420 px wide; the plot area runs from x = 64 to 408.
  for (double x : right) EXPECT_GT(x, 210.0);

  Fixture late;
  for (StepAnalysis& s : late.analyses) {
    RegionAnalysis& heel = s.regions[index_of(Region::Heel)];
    heel.series.area_mm2 = {0.0, 300.0, 900.0, 1500.0, 1800.0};
    heel.series.force_n = {0.0, 40.0, 120.0, 240.0, 300.0};
    heel.fit.model_force_n = {0.0, 45.0, 115.0, 245.0, 298.0};
  }
  std::vector<double> left = legend_xs(render_report_html(late.input()));
  ASSERT_EQ(left.size(), 5u);
  left.resize(3);
  for (double x : left) EXPECT_LT(x, 210.0);
}

TEST(ReportHtml, SaysWhyARegionHasNoChartsAndEscapesItsReasons) {
  const Fixture f;
  const std::string html = render_report_html(f.input());
  const std::size_t toe2 = html.find("<section id=\"toe2\">");
  ASSERT_NE(toe2, std::string::npos);
  const std::string section = html.substr(toe2, html.find("</section>", toe2) - toe2);
  EXPECT_TRUE(has(section,
                  "<p>2 steps with contact, 0 fitted; session-level fit: fit_failed "
                  "(&lt;2 frames)."));
  EXPECT_TRUE(has(section, "Fitted on the <b>contact ellipse</b> in 2 of 2 steps"));
  EXPECT_TRUE(has(section, "<p>No step of this region was fitted.</p>"));
  EXPECT_TRUE(has(section, "<br>not pooled: fewer than 3 steps &amp; no fit</th>"));
  EXPECT_FALSE(has(section, "<svg"));
}

TEST(ReportHtml, ListsEveryStepWithItsStatus) {
  const Fixture f;
  const std::string html = render_report_html(f.input());
  EXPECT_TRUE(has(html,
                  "<tr><td>L</td><td>2</td><td>1.100</td><td>1.700</td><td>0.600</td>"
                  "<td>655.5</td><td>ok</td><td>2.5</td></tr>"));
  EXPECT_TRUE(has(html,
                  "<tr><td>R</td><td>3</td><td>1.600</td><td>1.900</td><td>0.300</td>"
                  "<td>120.0</td><td>incomplete</td><td></td></tr>"));
}

TEST(ReportHtml, LinksOnlyWithinThePageAndNeverPrintsNanOrInf) {
  const Fixture f;
  const std::string html = render_report_html(f.input());
  std::size_t links = 0;
  for (std::size_t at = html.find("href=\""); at != std::string::npos;
       at = html.find("href=\"", at + 1)) {
    const std::size_t begin = at + 6;
    const std::string target = html.substr(begin, html.find('"', begin) - begin);
    ASSERT_EQ(target.front(), '#') << target;
    EXPECT_TRUE(has(html, "id=\"" + target.substr(1) + "\"")) << target;
    ++links;
  }
  EXPECT_EQ(links, kRegionCount + 2);  // the regions, left against right, the steps
  for (std::string_view loads : {"<script", "<link", "<img", "src=", "url(", "@import"}) {
    EXPECT_FALSE(has(html, loads)) << loads;
  }
  EXPECT_FALSE(has(html, "nan"));
  EXPECT_FALSE(has(html, "inf"));
}

}  // namespace
}  // namespace gaitmon::cli
