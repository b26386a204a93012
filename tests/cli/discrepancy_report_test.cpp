// The discrepancy report drawn from a result made by hand: what it says, how it colours the
// residual maps, what it leaves out, and that it stays one self-contained, well-nested page.
#include "src/cli/discrepancy_report.hpp"

#include <gtest/gtest.h>

#include <cstddef>
#include <string>
#include <string_view>

#include "test_support.hpp"

namespace gaitmon::cli {
namespace {

using test::kNaN;

using test::count;

// Every region x bin cell at the noise floor (ratio 1), apart from the three given here.
ResidualMap sample_map() {
  ResidualMap map;
  map.bins = 10;
  for (Region r : kRegions) {
    for (int b = 0; b < map.bins; ++b) {
      map.cells.push_back({.region = r,
                           .bin = b,
                           .samples = 40,
                           .rms_n = 2.0,
                           .bias_n = 0.0,
                           .noise_floor_n = 2.0});
    }
  }
  map.cells[0].rms_n = 6.0;   // heel, bin 0: three times the floor
  map.cells[1].rms_n = 4.0;   // heel, bin 1: twice
  map.cells[79].samples = 0;  // toes3_5, bin 9: no sample
  map.cells[79].rms_n = 0.0;
  return map;
}

DiscrepancyResult sample_result() {
  DiscrepancyResult r;
  r.steps = 24;
  r.step_regions = 150;
  r.step_regions_left_out = 12;
  r.frames = 9000;
  r.noise_floor_nrmse_pct = 0.8;
  r.nrmse_scale_n = 250.0;
  r.baseline_heldout_nrmse_pct = 4.0;
  r.extended_heldout_nrmse_pct = 1.5;
  r.gap_shrink_pct = 62.5;
  r.named_effects = {
      {"impact_transient", {{"amplitude_n", 40.0, 2.5}, {"duration_s", 0.03, kNaN}}}};
  r.candidates = {{.name = "impact_transient",
                   .params = {{"amplitude_n", 40.0, 2.5}, {"duration_s", 0.03, kNaN}},
                   .in_sample_nrmse_pct = 1.4,
                   .heldout_nrmse_pct = 1.5,
                   .shrink_pct = 62.5,
                   .delta_bic = -850.0},
                  {.name = "hysteresis",
                   .params = {{"strength", 0.0, kNaN}, {"transition_mm", 1.0, kNaN}},
                   .in_sample_nrmse_pct = 3.9,
                   .heldout_nrmse_pct = 3.95,
                   .shrink_pct = 1.2,
                   .delta_bic = 3.0}};
  r.map_before = sample_map();
  r.map_after = sample_map();
  r.where = {{.region = Region::Heel,
              .bin = 3,
              .samples = 40,
              .rms_n = 6.0,
              .bias_n = 1.25,
              .noise_floor_n = 2.0}};
  r.regions = {{.region = Region::Heel,
                .step_regions = 24,
                .baseline_heldout_nrmse_pct = 6.0,
                .extended_heldout_nrmse_pct = 1.0},
               {.region = Region::Toe2, .step_regions = 0}};
  r.per_step = {
      {.foot = Foot::Left, .step = 0, .baseline_nrmse_pct = 4.0, .extended_nrmse_pct = 1.5}};
  r.diagnostics = {.bias_per_phase_pct = {0.5, -0.25},
                   .lag1_autocorrelation = 0.8,
                   .runs_z = -12.0,
                   .effective_sample_fraction = 0.111,
                   .correlations = {{"rate", 0.5}}};
  r.zero_levels = {{.foot = Foot::Right,
                    .steps = 12,
                    .first_bits = 10.0,
                    .last_bits = 40.0,
                    .lowest_bits = 10.0,
                    .highest_bits = 40.0,
                    .scatter_bits = 1.0,
                    .range_pct_of_peak = 3.5,
                    .drifting = true,
                    .t_s = {},
                    .zero_bits = {}}};
  return r;
}

TEST(DiscrepancyReport, SaysWhatWasNamedAndHowMuchTheGapShrank) {
  const std::string html = render_discrepancy_html("walk-01", sample_result());
  EXPECT_NE(html.find("<title>gaitmon discrepancy: walk-01</title>"), std::string::npos);
  EXPECT_NE(html.find("<li><b>impact_transient</b>: amplitude_n = 40 &plusmn; 2.5; duration_s = "
                      "0.03 (no SE); </li>"),
            std::string::npos);
  EXPECT_NE(html.find("Held-out NRMSE 4.00 % &rarr; 1.50 %: the gap shrinks by <b>62.5 %</b>"),
            std::string::npos);
  EXPECT_NE(html.find("24 steps, 150 step-regions, 9000 frames (12 step-regions left out"),
            std::string::npos);
  EXPECT_NE(html.find("1 % is 2.50 N RMS). Noise floor 0.80 %."), std::string::npos);
  EXPECT_NE(html.find("<tr><td>hysteresis</td><td>3.95</td><td>1.2</td><td>3.90</td><td>0.0</td>"
                      "<td>3</td><td>strength = 0 (no SE)<br>transition_mm = 1 (no SE)<br>"
                      "</td></tr>"),
            std::string::npos);
  EXPECT_NE(html.find("<tr><td>heel</td><td>0.3-0.4</td><td>40</td><td>6.00</td><td>+1.25</td>"
                      "<td>2.00</td></tr>"),
            std::string::npos);
  EXPECT_NE(html.find("Lag-1 autocorrelation 0.800; runs test z -12.0; effective sample "
                      "fraction 0.111."),
            std::string::npos);
  EXPECT_NE(html.find("Bias per phase bin, % of peak force: +0.50 -0.25 "), std::string::npos);
  EXPECT_NE(html.find("<tr><td>rate</td><td>+0.500</td></tr>"), std::string::npos);
  EXPECT_NE(html.find("<tr><td>R</td><td>12</td><td>10.0</td><td>40.0</td><td>10.0</td>"
                      "<td>40.0</td><td>1.0</td><td>3.50</td><td><b>yes</b></td></tr>"),
            std::string::npos);
}

TEST(DiscrepancyReport, ColoursEachMapCellByItsResidualOverTheNoiseFloor) {
  const std::string html = render_discrepancy_html("walk-01", sample_result());
  // White at the floor, deep red at three times it, half way at twice; grey without samples.
  // Each colour is counted over both maps (before and after).
  EXPECT_EQ(count(html, R"x(fill="rgb(255,55,35)")x"), 2u);
  EXPECT_EQ(count(html, R"x(fill="rgb(255,155,145)")x"), 2u);
  EXPECT_EQ(count(html, R"x(fill="rgb(255,255,255)")x"), 2u * 77u);
  EXPECT_EQ(count(html, R"(fill="#eee")"), 2u);
  EXPECT_EQ(count(html, R"(text-anchor="middle">3.0</text>)"), 2u);
}

TEST(DiscrepancyReport, LeavesOutRegionsWithoutStepRegionsAndSectionsWithoutData) {
  const std::string html = render_discrepancy_html("walk-01", sample_result());
  // A region's label is in both maps; in the before/after bars only if it had step-regions.
  EXPECT_EQ(count(html, R"(font-size="12">heel</text>)"), 3u);
  EXPECT_EQ(count(html, R"(font-size="12">toe2</text>)"), 2u);
  // No zero channel, no ceiling count (-1), no second effect sought: none of their sections.
  EXPECT_EQ(html.find("Zero channel"), std::string::npos);
  EXPECT_EQ(html.find("A ceiling in the readings"), std::string::npos);
  EXPECT_EQ(html.find("On top of the first named effect"), std::string::npos);

  DiscrepancyResult with = sample_result();
  with.zero_changes = 276;
  with.zero_baseline_heldout_nrmse_pct = 0.4;
  with.zero_extended_heldout_nrmse_pct = 0.1;
  with.zero_gap_shrink_pct = 75.0;
  with.ceiling_plateau_steps = 0;
  with.second_candidates = with.candidates;
  const std::string more = render_discrepancy_html("walk-01", with);
  EXPECT_NE(more.find("Zero channel (276 step-to-step changes"), std::string::npos);
  EXPECT_NE(more.find("held-out NRMSE 0.400 % &rarr; 0.100 %, the gap shrinks by <b>75.0 %</b>"),
            std::string::npos);
  EXPECT_NE(more.find("A ceiling in the readings: 0 of 24 steps"), std::string::npos);
  EXPECT_NE(more.find("<h3>On top of the first named effect</h3>"), std::string::npos);
  EXPECT_EQ(count(more, "<tr><td>impact_transient</td>"), 2u);
}

TEST(DiscrepancyReport, SaysWhyTheMostLikelyCandidateWasNotNamed) {
  DiscrepancyResult r = sample_result();
  r.named_effects.clear();
  r.most_likely_candidate = "hysteresis";
  r.not_named_reason = "held-out NRMSE fell 1.2 % < 5 %";
  const std::string html = render_discrepancy_html("walk-01", r);
  EXPECT_NE(html.find("<li>none</li><li>the most likely candidate, hysteresis, is not named: "
                      "held-out NRMSE fell 1.2 % &lt; 5 %</li>"),
            std::string::npos);
  // Another candidate that passes is named where the most likely one does not.
  r.named_effects = sample_result().named_effects;
  ASSERT_FALSE(r.named_effects.empty());
  const std::string other = render_discrepancy_html("walk-01", r);
  EXPECT_EQ(other.find("<li>none</li>"), std::string::npos);
  EXPECT_NE(other.find("<li><b>" + r.named_effects.front().name + "</b>"), std::string::npos);
  EXPECT_NE(other.find("<li>the most likely candidate, hysteresis, is not named"),
            std::string::npos);
}

TEST(DiscrepancyReport, PlotsEachFootsZeroAgainstTime) {
  DiscrepancyResult r = sample_result();
  const std::string without = render_discrepancy_html("walk-01", r);
  EXPECT_EQ(without.find("heel strike time"), std::string::npos);  // no course, no plot
  r.zero_levels[0].t_s = {1.0, 2.1, 3.2};
  r.zero_levels[0].zero_bits = {10.0, 25.0, 40.0};
  ZeroLevelDrift left;
  left.t_s = {0.5, 1.6};
  left.zero_bits = {12.0, 12.0};
  r.zero_levels.push_back(left);
  const std::string html = render_discrepancy_html("walk-01", r);
  EXPECT_EQ(count(html, "<polyline"), count(without, "<polyline") + 2);
  // Right: from the lowest reading at the first time to the highest at the last, on the axes
  // of x 50..590 and y 170 (10 bits) .. 10 (40 bits), time 0.5..3.2 s.
  EXPECT_NE(html.find(R"(stroke="#c05621" stroke-width="1.5" points="150.0,170.0 370.0,90.0 )"
                      R"(590.0,10.0 ")"),
            std::string::npos);
  EXPECT_NE(html.find("foot L</text>"), std::string::npos);
  EXPECT_NE(html.find(">40</text>"), std::string::npos);
  EXPECT_NE(html.find(">3 s</text>"), std::string::npos);
}

TEST(DiscrepancyReport, EscapesTheSessionNameAndNeverPrintsNanOrInf) {
  DiscrepancyResult r = sample_result();
  r.per_step.clear();  // an empty per-step plot has nothing to scale
  const std::string html = render_discrepancy_html(R"(<script>"a&b"</script>)", r);
  EXPECT_EQ(html.find("<script"), std::string::npos);
  EXPECT_NE(html.find("Model-data discrepancy: &lt;script&gt;&quot;a&amp;b&quot;&lt;/script&gt;"),
            std::string::npos);
  EXPECT_EQ(html.find("nan"), std::string::npos);
  EXPECT_EQ(html.find("inf"), std::string::npos);

  DiscrepancyResult one = sample_result();  // one step: the x scale's span is 0
  EXPECT_EQ(render_discrepancy_html("walk-01", one).find("nan"), std::string::npos);
}

TEST(DiscrepancyReport, IsOneSelfContainedWellNestedPage) {
  const std::string html = render_discrepancy_html("walk-01", sample_result());
  EXPECT_EQ(html.rfind("<!DOCTYPE html>", 0), 0u);
  EXPECT_EQ(html.substr(html.size() - 8), "</html>\n");
  for (std::string_view loads : {"<script", "<link", "<img", "src=", "href=", "url(", "@import"}) {
    EXPECT_EQ(html.find(loads), std::string::npos) << loads;
  }
  for (std::string_view tag : {"svg", "table", "tr", "li", "ul", "p", "h2", "b"}) {
    const std::string open = "<" + std::string(tag);
    EXPECT_EQ(count(html, open + ">") + count(html, open + " "),
              count(html, "</" + std::string(tag) + ">"))
        << tag;
  }
}

}  // namespace
}  // namespace gaitmon::cli
