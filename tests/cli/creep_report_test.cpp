// What `gaitmon creep` writes, from findings made by hand: the verdict, creep.json's fields and
// nulls, the spread it prints, and where the forest plot puts each recording and the mean.
#include "src/cli/creep_report.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>
#include <vector>

#include "test_support.hpp"

namespace gaitmon::cli {
namespace {

using test::kNaN;

// Two walks that show a creep, 0.30 and 0.34 +- 0.01 (tau 1.0 and 1.2 +- 0.1 s), and one whose
// zeros do not (0.20, no SE). Weighted alike, their mean is the midpoint with SE 0.01 / sqrt 2;
// the spread is 2 SE each side: chi-square 8 on 1 degree of freedom, p 0.0047, under 0.01.
CreepFindings two_walks_apart() {
  CreepFindings f;
  const MeasuredCreep a_used{0.30, 0.01, 1.0, 0.1}, b_used{0.34, 0.01, 1.2, 0.1};
  const MeasuredCreep c_used{0.20, kNaN, 0.5, kNaN};
  f.recordings = {{"a.csv", 30, a_used, {0.30, 0.008, 1.0, 0.1}, a_used, 0.4, 0.1, true, 0.0},
                  {"b.csv", 31, b_used, b_used, {0.34, 0.006, 1.2, 0.05}, 0.4, 0.1, true, 4.9},
                  {"c.csv", 29, c_used, c_used, c_used, 0.2, 0.19, false, 2.5}};
  CreepAgreement a;
  a.recordings = 2;
  a.mean = {0.32, 0.01 / std::sqrt(2.0), 1.1, 0.1 / std::sqrt(2.0)};
  a.gain_chi2 = 8.0;
  a.gain_p = 0.00468;
  a.tau_chi2 = 2.0;
  a.tau_p = 0.157;
  a.agree = false;
  f.agreement = a;
  return f;
}

std::vector<double> numbers_after(const std::string& text, const std::string& attribute) {
  std::vector<double> out;
  const std::regex re(attribute + R"(="([-0-9.]+)\")");
  for (auto it = std::sregex_iterator(text.begin(), text.end(), re); it != std::sregex_iterator();
       ++it) {
    out.push_back(std::stod((*it)[1].str()));
  }
  return out;
}

// Each error is the larger of the two a fit gives; the curvature's alone where the sandwich has
// none, and none where the curvature has none.
TEST(CreepReport, AWalksErrorsAreTheLargerOfTheCurvaturesAndTheSandwichs) {
  const MeasuredCreep c = larger_errors({"gain", 0.3, 0.01, 0.02}, {"tau_s", 2.0, 0.2, 0.1});
  EXPECT_EQ(c.gain, 0.3);
  EXPECT_EQ(c.gain_se, 0.02);
  EXPECT_EQ(c.tau_s, 2.0);
  EXPECT_EQ(c.tau_se_s, 0.2);
  const MeasuredCreep no_sandwich =
      larger_errors({"gain", 0.3, 0.01, kNaN}, {"tau_s", 2.0, kNaN, kNaN});
  EXPECT_EQ(no_sandwich.gain_se, 0.01);
  EXPECT_TRUE(std::isnan(no_sandwich.tau_se_s));
}

TEST(CreepReport, TheVerdictFollowsTheAgreementAndHowManyShowACreep) {
  CreepFindings f = two_walks_apart();
  EXPECT_EQ(f.verdict(), CreepVerdict::Disagree);
  f.agreement->agree = true;
  EXPECT_EQ(f.verdict(), CreepVerdict::Agree);
  f.agreement.reset();
  f.recordings[1].shown = false;
  EXPECT_EQ(f.verdict(), CreepVerdict::OneShows);
  f.recordings[0].shown = false;
  EXPECT_EQ(f.verdict(), CreepVerdict::NoneShows);
  EXPECT_EQ(verdict_name(CreepVerdict::NoneShows), "none_shows");
  EXPECT_NE(verdict_text(f).find("no recording shows a creep"), std::string::npos);
}

TEST(CreepReport, TheJsonHoldsEveryRecordingWithNullWhereThereIsNoStandardError) {
  CreepFindings f = two_walks_apart();
  f.config_creep = {0.1, 2.0};
  const nlohmann::json j = nlohmann::json::parse(creep_json_text(f));
  EXPECT_EQ(j["verdict"], "disagree");
  EXPECT_TRUE(j["sensor_creep_to_paste"].is_null());
  EXPECT_EQ(j["config_sensor_creep"]["gain"], 0.1);
  ASSERT_EQ(j["recordings"].size(), 3u);
  EXPECT_EQ(j["recordings"][1]["session"], "b.csv");
  EXPECT_EQ(j["recordings"][1]["gain"], 0.34);
  EXPECT_TRUE(j["recordings"][2]["gain_se"].is_null());
  EXPECT_TRUE(j["recordings"][2]["tau_se_s"].is_null());
  EXPECT_EQ(j["recordings"][0]["gain_se_curvature"], 0.008);
  EXPECT_EQ(j["recordings"][0]["gain_se_sandwich"], 0.01);
  EXPECT_EQ(j["recordings"][1]["tau_se_sandwich_s"], 0.05);
  EXPECT_TRUE(j["recordings"][2]["gain_se_sandwich"].is_null());
  EXPECT_FALSE(j["recordings"][2]["shows_creep"].get<bool>());
  EXPECT_EQ(j["agreement"]["degrees_of_freedom"], 1);
  EXPECT_EQ(j["agreement"]["gain_chi2"], 8.0);
  EXPECT_EQ(j["recordings"][1]["loaded_cells_at_zero_pct"], 4.9);

  f.agreement->agree = true;
  const nlohmann::json agreed = nlohmann::json::parse(creep_json_text(f));
  EXPECT_EQ(agreed["verdict"], "agree");
  EXPECT_EQ(agreed["sensor_creep_to_paste"]["gain"], 0.32);
  EXPECT_EQ(agreed["sensor_creep_to_paste"]["tau_s"], 1.1);
}

// The note on cells that rest at 0 comes where one recording has 5 % of its loaded cells there or
// more, counts those recordings and gives the most, and is on the page too.
TEST(CreepReport, CellsAtZeroAreNotedFromFivePerCentOfTheLoadedOnes) {
  CreepFindings f = two_walks_apart();
  EXPECT_EQ(cells_at_zero_note(f.recordings), "");
  EXPECT_EQ(render_creep_html(f).find("rest at 0"), std::string::npos);
  f.recordings[2].cells_at_zero_pct = 5.0;
  f.recordings[0].cells_at_zero_pct = 26.4;
  const std::string note = cells_at_zero_note(f.recordings);
  EXPECT_NE(note.find("in 2 of the 3 recordings 5 % or more of the cells the steps loaded rest at "
                      "0 in the swing (up to 26 %)"),
            std::string::npos)
      << note;
  EXPECT_NE(note.find("the gain comes out low"), std::string::npos) << note;
  EXPECT_NE(render_creep_html(f).find("(up to 26 %)"), std::string::npos);
  EXPECT_NE(render_creep_html(f).find("<td>26</td>"), std::string::npos);
}

// The spread printed is of the recordings in the mean: the one whose zeros show no creep (0.20)
// is not its lower end.
TEST(CreepReport, TheSpreadIsOfTheRecordingsThatShowTheCreep) {
  const CreepFindings f = two_walks_apart();
  const std::string text = agreement_text(*f.agreement, f.recordings);
  EXPECT_NE(text.find("their gains span 0.3 to 0.34, their taus 1 to 1.2 s"), std::string::npos)
      << text;
  EXPECT_NE(text.find("chi-square 8 on 1 degrees of freedom"), std::string::npos) << text;
  EXPECT_NE(on_top_of_config({0.25, 3.0}).find("gain 0.25, tau 3 s"), std::string::npos);
  EXPECT_EQ(on_top_of_config({0.0, 1.0}), "");
}

// In each panel the mean (0.32) sits midway between the two walks (0.30, 0.34); their 95 %
// intervals are equally wide, each 2 x 1.96 SE; the mean's band is 1 / sqrt 2 of one; the walk
// without an SE has no interval and a hollow dot, left of both.
TEST(CreepReport, TheForestPlotPutsEachWalkAndTheMeanWhereTheirValuesAre) {
  const std::string page = render_creep_html(two_walks_apart());
  EXPECT_EQ(test::count(page, "<svg "), 2u);
  EXPECT_EQ(test::count(page, "<html"), 1u);
  EXPECT_EQ(test::count(page, "</html>"), 1u);
  EXPECT_EQ(page.find("<script"), std::string::npos);
  EXPECT_EQ(page.find("href="), std::string::npos);
  EXPECT_EQ(page.find("src="), std::string::npos);
  EXPECT_NE(page.find("they disagree"), std::string::npos);

  const std::string gain =
      page.substr(page.find("<svg "), page.find("</svg>") - page.find("<svg "));
  const std::vector<double> dots = numbers_after(gain, "class=\"estimate\" cx");
  ASSERT_EQ(dots.size(), 3u);
  EXPECT_LT(dots[2], dots[0]);
  EXPECT_LT(dots[0], dots[1]);
  std::vector<double> x1, x2;
  const std::regex interval(R"re(class="interval" x1="([-0-9.]+)" x2="([-0-9.]+)")re");
  for (auto it = std::sregex_iterator(gain.begin(), gain.end(), interval);
       it != std::sregex_iterator(); ++it) {
    x1.push_back(std::stod((*it)[1].str()));
    x2.push_back(std::stod((*it)[2].str()));
  }
  ASSERT_EQ(x1.size(), 2u);
  const double width_a = x2[0] - x1[0];
  const double width_b = x2[1] - x1[1];
  EXPECT_NEAR(width_a, width_b, 0.2);
  const double px_per_unit = (dots[1] - dots[0]) / 0.04;
  EXPECT_NEAR(width_a, 2 * 1.96 * 0.01 * px_per_unit, 0.2);
  const std::vector<double> mean = numbers_after(gain, "class=\"mean\" x1");
  ASSERT_EQ(mean.size(), 1u);
  EXPECT_NEAR(mean[0], 0.5 * (dots[0] + dots[1]), 0.1);
  const std::vector<double> band = numbers_after(gain, "class=\"mean-band\" x");
  ASSERT_EQ(band.size(), 1u);
  EXPECT_NEAR(mean[0] - band[0], width_a / 2 / std::sqrt(2.0), 0.2);
  EXPECT_NE(gain.find("fill=\"#ffffff\" stroke=\"#999999\""), std::string::npos);
  EXPECT_EQ(test::count(page, "class=\"interval\""), 4u);
}

}  // namespace
}  // namespace gaitmon::cli
