// `gaitmon analyze` end to end: its files, their headers, the report, and its errors.
#include <fcntl.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <pty.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "gaitmon/config.hpp"
#include "gaitmon/stance.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;

const auto run = &test::run_gaitmon;

std::vector<std::string> lines_of(const fs::path& path) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

std::vector<std::string> fields(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  for (std::string f; std::getline(ss, f, ',');) out.push_back(f);
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}

std::string read_all(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

/// One column of regions.csv over the heel's rows, as written.
std::vector<std::string> heel_column(const fs::path& regions_csv, std::size_t column) {
  std::vector<std::string> values;
  for (const std::string& line : lines_of(regions_csv)) {
    const auto f = fields(line);
    if (f.size() > column && f[2] == "heel") values.push_back(f[column]);
  }
  return values;
}

nlohmann::json settings_of(const fs::path& out_dir) {
  return nlohmann::json::parse(read_all(out_dir / "session.json")).at("settings");
}

/// A 6 s simulated walk, analysed once with --report.
struct Analysed {
  fs::path dir;
  std::string output;
  int status = -1;
};

const Analysed& analysed() {
  static const Analysed a = [] {
    Analysed r;
    r.dir = test::scratch_dir("analyze-cmd");
    std::string out =
        run("simulate --size 37-38 --duration 6 --seed 2 --out " + (r.dir / "s.csv").string(),
            &r.status);
    if (r.status != 0) {
      r.output = out;
      return r;
    }
    r.output = run("analyze " + (r.dir / "s.csv").string() + " --out " + (r.dir / "out").string() +
                       " --report",
                   &r.status);
    return r;
  }();
  return a;
}

TEST(AnalyzeCommand, WritesStepsWithTheTotalNrmse) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  const auto lines = lines_of(a.dir / "out" / "steps.csv");
  ASSERT_GE(lines.size(), 5u);
  EXPECT_EQ(lines[0],
            "foot,step,t_heel_strike_s,t_toe_off_s,stance_s,peak_force_n,status,nrmse_total_pct");
  int ok = 0;
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const auto f = fields(lines[i]);
    ASSERT_EQ(f.size(), 8u) << lines[i];
    if (f[6] == "ok") {
      ++ok;
      EXPECT_FALSE(f[7].empty()) << lines[i];
      EXPECT_GT(std::stod(f[7]), 0.0);
    } else {
      EXPECT_EQ(f[6], "incomplete");
      EXPECT_TRUE(f[7].empty()) << lines[i];
    }
  }
  EXPECT_GE(ok, 6) << "6 s at 1.1 s strides: at least 3 whole steps per foot";
}

TEST(AnalyzeCommand, WritesARowPerOkStepAndRegion) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  std::vector<std::string> ok_steps;
  for (const auto& line : lines_of(a.dir / "out" / "steps.csv")) {
    const auto f = fields(line);
    if (f.size() > 6 && f[6] == "ok") ok_steps.push_back(f[0] + "," + f[1]);
  }
  const auto lines = lines_of(a.dir / "out" / "regions.csv");
  ASSERT_FALSE(lines.empty());
  const std::string fixed =
      "foot,step,region,status,frames,peak_force_n,peak_area_mm2,A_mm,B_mm,C_mm,d0_mm,"
      "kbar_n_per_mm3,n,cbar_ns_per_mm3,m,se_kbar,se_n,se_cbar,se_m,nrmse_pct";
  EXPECT_EQ(lines[0].substr(0, fixed.size()), fixed);
  const std::size_t columns = fields(lines[0]).size();
  ASSERT_EQ(lines.size(), 1 + 8 * ok_steps.size());
  std::map<std::string, int> per_step;
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const auto f = fields(lines[i]);
    ASSERT_EQ(f.size(), columns) << lines[i];
    ++per_step[f[0] + "," + f[1]];
    EXPECT_TRUE(f[3] == "ok" || f[3] == "no_contact" || f[3].starts_with("fit_failed:"))
        << lines[i];
    if (f[3] == "ok" && f[2] == "heel") {
      EXPECT_EQ(f[9], "69.9") << "heel C of size 37-38, Appendix I";
      EXPECT_EQ(f[10], "16.4") << "heel d0 of size 37-38, Appendix I";
    }
  }
  for (const auto& s : ok_steps) EXPECT_EQ(per_step[s], 8) << s;
}

TEST(AnalyzeCommand, WritesTheSessionLevelFitsAsJson) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  const auto j = nlohmann::json::parse(read_all(a.dir / "out" / "session.json"));
  EXPECT_EQ(j.at("settings").at("model"), "correct");
  EXPECT_EQ(j.at("settings").at("fit"), "identifiable");
  EXPECT_EQ(j.at("settings").at("area"), "footprint");
  EXPECT_NE(j.at("note").get<std::string>().find("declared"), std::string::npos);
  for (const char* region : {"heel", "midfoot_posterior", "midfoot_anterior", "met1_2", "met3_5",
                             "toe1", "toe2", "toes3_5"}) {
    SCOPED_TRACE(region);
    const auto& r = j.at("regions").at(region);
    const auto& fit = r.at("session_fit");
    EXPECT_EQ(fit.at("status"), "ok");
    for (const char* p :
         {"A_mm", "B_mm", "C_mm", "d0_mm", "kbar_n_per_mm3", "n", "cbar_ns_per_mm3", "m"}) {
      EXPECT_TRUE(fit.at("parameters").at(p).at("value").is_number());
      EXPECT_TRUE(r.at("across_steps").at(p).at("median").is_number());
      EXPECT_TRUE(r.at("across_steps").at(p).at("iqr").is_number());
    }
    EXPECT_FALSE(fit.at("parameters").at("C_mm").at("free").get<bool>());
    EXPECT_TRUE(fit.at("parameters").at("kbar_n_per_mm3").at("free").get<bool>());
    EXPECT_GT(fit.at("nrmse_pct").get<double>(), 0.0);
  }
  EXPECT_DOUBLE_EQ(j.at("regions").at("heel").at("appendix_i").at("mean").at("d0_mm"), 16.4);
}

// The heel's steps are pooled (pooling.hpp): every heel row fitted Ok carries its pooled kbar, n,
// cbar, m, session.json counts the same steps, and the pooled standard errors, which hold the
// measurement chain's shared error, are smaller than the steps' own with it (se_*_total) because
// each step borrows from the others. The pool's mean has a standard error with that error too,
// printed in the summary.
TEST(AnalyzeCommand, WritesEachStepsPooledEstimatesAndThePoolPerRegion) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  const auto lines = lines_of(a.dir / "out" / "regions.csv");
  ASSERT_FALSE(lines.empty());
  const auto header = fields(lines[0]);
  const auto column = [&](const std::string& name) {
    const auto it = std::find(header.begin(), header.end(), name);
    EXPECT_NE(it, header.end()) << name;
    return static_cast<std::size_t>(it - header.begin());
  };
  const std::size_t se_kbar = column("se_kbar_total");
  const std::size_t pooled_columns[] = {column("kbar_pooled"), column("n_pooled"),
                                        column("cbar_pooled"), column("m_pooled")};
  const std::size_t se_kbar_pooled = column("se_kbar_pooled");
  int heel_pooled = 0;
  std::vector<double> own_se, pooled_se;
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const auto f = fields(lines[i]);
    if (f[2] != "heel" || f[3] != "ok") continue;
    for (std::size_t c : pooled_columns) ASSERT_FALSE(f[c].empty()) << lines[i];
    ++heel_pooled;
    EXPECT_GT(std::stod(f[pooled_columns[0]]), 0.0);
    own_se.push_back(std::stod(f[se_kbar]));
    pooled_se.push_back(std::stod(f[se_kbar_pooled]));
  }
  const auto j = nlohmann::json::parse(read_all(a.dir / "out" / "session.json"));
  const auto& pooling = j.at("regions").at("heel").at("pooling");
  EXPECT_TRUE(pooling.at("pooled").get<bool>());
  EXPECT_EQ(pooling.at("steps").get<int>(), heel_pooled);
  EXPECT_GE(heel_pooled, 6);
  EXPECT_TRUE(pooling.at("mean").at("cbar_ns_per_mm3").is_number());
  EXPECT_GE(pooling.at("between_step_sd").at("ln_kbar").get<double>(), 0.0);
  EXPECT_NE(pooling.at("note").get<std::string>().find("read this mean: session_fit's standard "
                                                       "errors are its Jacobian's"),
            std::string::npos);
  // The mean's SE holds the chain's shared error ([pooling] of the shipped config: heel kbar
  // 4 %, n 0.02) beside the steps' scatter: sqrt(se_steps^2 + (mean x 0.04)^2) for kbar.
  const auto part = [&](const char* field, const char* parameter) {
    return pooling.at(field).at(parameter).get<double>();
  };
  EXPECT_DOUBLE_EQ(part("chain_sd", "ln_kbar"), 0.04);
  EXPECT_DOUBLE_EQ(part("chain_sd", "n"), 0.02);
  const double kbar = part("mean", "kbar_n_per_mm3");
  EXPECT_NEAR(part("se", "kbar_n_per_mm3"),
              std::hypot(part("se_steps", "kbar_n_per_mm3"), 0.04 * kbar), 1e-12 * kbar);
  EXPECT_NEAR(part("se", "n"), std::hypot(part("se_steps", "n"), 0.02), 1e-12);
  EXPECT_GT(part("se_steps", "kbar_n_per_mm3"), 0.0);
  // The summary prints the heel's pooled kbar with that SE.
  EXPECT_NE(a.output.find("pooled over the session, +- one standard error"), std::string::npos)
      << a.output;
  EXPECT_NE(a.output.find(fmt::format("{:.4f} +- {:.4f}", kbar, part("se", "kbar_n_per_mm3"))),
            std::string::npos)
      << a.output;
  std::sort(own_se.begin(), own_se.end());
  std::sort(pooled_se.begin(), pooled_se.end());
  EXPECT_LT(pooled_se[pooled_se.size() / 2], own_se[own_se.size() / 2]);
  // A step's pooled kbar leans on the mean and carries its chain error.
  for (const double se : pooled_se) EXPECT_GT(se, 0.04 * 0.9 * kbar);
}

// Each step's standard errors with the chain's shared error, worked here from the shipped
// [pooling] SDs of the heel (kbar 4 %, n 0.02, cbar 13 %, m 0.06; no step SDs) and of met3_5
// (chain 4.5 %, 0.03, 12 %, 0.07 and the step's own 7.5 %, 0.045, 25 %, 0.16): on the log scale
// for kbar and cbar, as the fit's covariance is. With --m-per-session the shared m's standard
// error and [pooling.m_per_session]'s SD of m (0.06) make se_m_total, and reach cbar through its
// slope.
TEST(AnalyzeCommand, WritesEachStepsStandardErrorsWithTheChainsSharedError) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  const auto lines = lines_of(a.dir / "out" / "regions.csv");
  ASSERT_FALSE(lines.empty());
  const auto header = fields(lines[0]);
  const std::vector<std::string> tail = {"se_kbar_total", "se_n_total", "se_cbar_total",
                                         "se_m_total"};
  ASSERT_GE(header.size(), tail.size());
  EXPECT_EQ(std::vector<std::string>(header.end() - 4, header.end()), tail);
  const std::size_t total = header.size() - 4;
  const auto near = [](double got, double expected, const std::string& line) {
    EXPECT_NEAR(got, expected, 0.006 * expected) << line;
  };
  const double kMRangeSe = 0.56 / std::sqrt(3.0);  // [fit] m from 0.82 to 1.38
  int heel = 0, met3_5 = 0, held = 0;
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const auto f = fields(lines[i]);
    if (f[3] != "ok") {
      for (std::size_t c = total; c < f.size(); ++c) EXPECT_TRUE(f[c].empty()) << lines[i];
      continue;
    }
    // Where the step leaves m undetermined, its SE beyond the range's 0.56 / sqrt 3, m's variance
    // is held at the range's (within_m_range): se_m_total is then that with the SDs, under the
    // fit's own. Elsewhere every total is at least the fit's own.
    const bool m_held = !f[total + 3].empty() && std::stod(f[18]) > kMRangeSe;
    if (m_held) {
      ++held;
      EXPECT_GE(std::stod(f[total + 3]), kMRangeSe * (1 - 5e-3)) << lines[i];
      EXPECT_LT(std::stod(f[total + 3]), std::stod(f[18])) << lines[i];
      continue;
    }
    for (std::size_t k = 0; k < 4; ++k) {
      if (f[total + k].empty()) continue;  // a parameter the step does not determine
      EXPECT_GE(std::stod(f[total + k]), std::stod(f[15 + k]) * (1 - 5e-3)) << lines[i];
    }
    const double kbar = std::stod(f[11]), cbar = std::stod(f[13]);
    const auto root_sum_square = [](double a, double b, double c) {
      return std::sqrt(a * a + b * b + c * c);
    };
    if (f[2] == "met3_5" && !f[total].empty() && !f[total + 3].empty()) {
      ++met3_5;
      near(std::stod(f[total]), kbar * root_sum_square(std::stod(f[15]) / kbar, 0.045, 0.075),
           lines[i]);
      near(std::stod(f[total + 1]), root_sum_square(std::stod(f[16]), 0.03, 0.045), lines[i]);
      near(std::stod(f[total + 2]), cbar * root_sum_square(std::stod(f[17]) / cbar, 0.12, 0.25),
           lines[i]);
      near(std::stod(f[total + 3]), root_sum_square(std::stod(f[18]), 0.07, 0.16), lines[i]);
    }
    if (f[2] != "heel") continue;
    ++heel;
    near(std::stod(f[total]), kbar * std::hypot(std::stod(f[15]) / kbar, 0.04), lines[i]);
    near(std::stod(f[total + 1]), std::hypot(std::stod(f[16]), 0.02), lines[i]);
    near(std::stod(f[total + 2]), cbar * std::hypot(std::stod(f[17]) / cbar, 0.13), lines[i]);
    near(std::stod(f[total + 3]), std::hypot(std::stod(f[18]), 0.06), lines[i]);
  }
  EXPECT_GE(heel, 6);
  EXPECT_GE(met3_5, 6);
  EXPECT_GE(held, 6);

  int status = -1;
  const fs::path out = a.dir / "m-per-session-total";
  const std::string printed =
      run("analyze " + (a.dir / "s.csv").string() + " --out " + out.string() + " --m-per-session",
          &status);
  ASSERT_EQ(status, 0) << printed;
  const double se_m = nlohmann::json::parse(read_all(out / "session.json"))
                          .at("regions")
                          .at("heel")
                          .at("m_per_session")
                          .at("se")
                          .get<double>();
  int shared = 0;
  for (const auto& line : lines_of(out / "regions.csv")) {
    const auto f = fields(line);
    if (f[2] != "heel" || f[3] != "ok") continue;
    ++shared;
    near(std::stod(f[18]), se_m, line);
    near(std::stod(f[total + 3]), std::hypot(se_m, 0.06), line);
    // The shared m's error moves this step's cbar: more than the chain's 3 % of cbar alone.
    const double cbar = std::stod(f[13]);
    EXPECT_GT(std::stod(f[total + 2]), cbar * std::hypot(std::stod(f[17]) / cbar, 0.03) * 1.01)
        << line;
  }
  EXPECT_EQ(shared, heel);
}

TEST(AnalyzeCommand, ReportIsSelfContained) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  const std::string html = read_all(a.dir / "out" / "report.html");
  EXPECT_NE(html.find("<svg"), std::string::npos);
  EXPECT_EQ(html.find("http://"), std::string::npos);
  EXPECT_EQ(html.find("https://"), std::string::npos);
  EXPECT_EQ(html.find("<script"), std::string::npos);
  EXPECT_NE(html.find("force (N)"), std::string::npos) << "axes carry units";
  EXPECT_NE(html.find("Appendix I"), std::string::npos);
  EXPECT_NE(html.find("pooled mean &plusmn; SE with the chain"), std::string::npos);
  EXPECT_NE(html.find("</html>"), std::string::npos);
}

TEST(AnalyzeCommand, PrintsASummaryPerRegion) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  for (const char* region : {"heel", "met3_5", "toes3_5"}) {
    EXPECT_NE(a.output.find(region), std::string::npos) << a.output;
  }
  EXPECT_NE(a.output.find("NRMSE"), std::string::npos) << a.output;
  EXPECT_EQ(a.output.find("warning"), std::string::npos) << a.output;
}

// A median that most steps' fits left at a bound of its range is marked, with a footnote: the
// toes' damping, which their whole-cell areas cannot show, and nothing at the heel, whose
// footprint determines all four. The marks, and session.json's counts of the steps at a bound,
// agree with regions.csv's at_bound column.
TEST(AnalyzeCommand, MarksTheMediansThatMostStepsLeftAtABound) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  EXPECT_NE(a.output.find("\n* at a bound of its fit range in at least half of the region's "
                          "steps: the data do not determine it there (regions.csv: at_bound)\n"),
            std::string::npos)
      << a.output;
  const std::vector<std::string> lines = lines_of(a.dir / "out" / "regions.csv");
  ASSERT_FALSE(lines.empty());
  const std::vector<std::string> header = fields(lines.front());
  const auto column = [&](const std::string& name) {
    return static_cast<std::size_t>(std::find(header.begin(), header.end(), name) - header.begin());
  };
  const std::array<std::string, 4> params = {"kbar_n_per_mm3", "n", "cbar_ns_per_mm3", "m"};
  std::map<std::string, std::pair<int, std::array<int, 4>>> counts;  // ok rows, at a bound
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const auto f = fields(lines[i]);
    if (f[column("status")] != "ok") continue;
    auto& [ok, at_bound] = counts[f[2]];
    ++ok;
    const std::string bound = ";" + f[column("at_bound")] + ";";
    for (std::size_t p = 0; p < params.size(); ++p) {
      if (bound.find(";" + params[p] + ";") != std::string::npos) ++at_bound[p];
    }
  }
  std::map<std::string, std::array<bool, 4>> marks;
  std::istringstream summary(a.output);
  // The medians' table ends at its note; the pooled table below it names the regions too.
  for (std::string line; std::getline(summary, line) && !line.starts_with("medians across");) {
    std::istringstream words(line);
    std::string region, fitted, contact;
    std::array<std::string, 4> values;
    words >> region >> fitted >> contact >> values[0] >> values[1] >> values[2] >> values[3];
    if (!counts.count(region)) continue;
    for (std::size_t p = 0; p < params.size(); ++p) marks[region][p] = values[p].back() == '*';
  }
  ASSERT_EQ(marks.size(), counts.size()) << a.output;
  const auto j = nlohmann::json::parse(read_all(a.dir / "out" / "session.json"));
  for (const auto& [region, c] : counts) {
    const auto& at_bound = j.at("regions").at(region).at("steps_at_bound");
    for (std::size_t p = 0; p < params.size(); ++p) {
      EXPECT_EQ(marks[region][p], 2 * c.second[p] >= c.first) << region << " " << params[p];
      EXPECT_EQ(at_bound.at(params[p]).get<int>(), c.second[p]) << region << " " << params[p];
    }
  }
  EXPECT_TRUE(marks["toes3_5"][2]) << a.output;
  EXPECT_EQ(marks["heel"], (std::array<bool, 4>{})) << a.output;
}

// What the summary line of a session.json section (drift or asymmetry) is checked against.
struct NamedSection {
  std::string key;          ///< in session.json's regions
  std::string pct, se_pct;  ///< the change in per cent and its standard error
  std::string ln, se_ln;    ///< the same on the log scale
  std::string steps;        ///< a count of the steps it rests on, at least min_steps
  int min_steps = 0;
  std::string not_estimated, none, named;  ///< the summary's three kinds of line
};

const NamedSection kDrift{"drift",
                          "pct_per_min",
                          "se_pct_per_min",
                          "ln_slope_per_min",
                          "se_ln_slope_per_min",
                          "steps",
                          5,
                          "drift: not estimated; no region but the toes has 5 steps spanning 30 s "
                          "or more with kbar or cbar off its bounds",
                          "no region's kbar or cbar drifts over the session by 3 standard errors "
                          "or more (the toes' are in session.json only)",
                          "drift over the session, % per minute (session.json: drift): "};

const NamedSection kAsymmetry{
    "asymmetry",
    "right_over_left_pct",
    "se_right_over_left_pct",
    "ln_right_over_left",
    "se_ln_right_over_left",
    "left_steps",
    3,
    "left against right: not compared; no region but the toes has 3 steps of each foot with kbar "
    "or cbar off its bounds",
    "no region's kbar or cbar differs between the feet by 3 standard errors or more (the toes' "
    "are in session.json only)",
    "right foot against left, % (session.json: asymmetry): "};

// session.json gives each region's kbar and cbar trend over the session, or their difference
// between the feet; the summary names exactly those of the regions but the toes whose |z| reaches
// 3, with their change and standard error, or says that none does. Returns the summary's line.
std::string check_named_outputs(const fs::path& out, const std::string& output,
                                const NamedSection& section) {
  const auto j = nlohmann::json::parse(read_all(out / "session.json"));
  std::vector<std::string> clear;
  int estimated = 0;
  for (const auto& [region, r] : j.at("regions").items()) {
    for (const std::string name : {"kbar", "cbar"}) {
      const auto& t = r.at(section.key).at(name);
      if (t.is_null()) continue;
      const double pct = t.at(section.pct).get<double>();
      const double se = t.at(section.se_pct).get<double>();
      const double b = t.at(section.ln).get<double>();
      const double se_b = t.at(section.se_ln).get<double>();
      EXPECT_GT(se_b, 0.0) << region << " " << name;
      EXPECT_NEAR(pct, 100.0 * std::expm1(b), 1e-9 * std::abs(pct));
      EXPECT_NEAR(se, 100.0 * std::exp(b) * se_b, 1e-9 * se);
      EXPECT_NEAR(t.at("z").get<double>(), b / se_b, 1e-9 * std::abs(b / se_b));
      EXPECT_LE(t.at(section.steps).get<int>(), r.at("steps_fitted").get<int>());
      EXPECT_GE(t.at(section.steps).get<int>(), section.min_steps);
      if (region.rfind("toe", 0) == 0) continue;
      ++estimated;
      if (std::abs(b / se_b) >= 3.0) {
        clear.push_back(fmt::format("{} {} {:+.1f} +- {:.1f}", region, name, pct, se));
      }
    }
  }
  if (estimated == 0) {
    EXPECT_NE(output.find("\n" + section.not_estimated + "\n"), std::string::npos) << output;
    return section.not_estimated;
  }
  EXPECT_TRUE(j.at("regions").at("heel").at(section.key).at("kbar").is_object());
  if (clear.empty()) {
    EXPECT_NE(output.find("\n" + section.none + "\n"), std::string::npos) << output;
    return section.none;
  }
  const auto at = output.find("\n" + section.named);
  if (at == std::string::npos) {
    ADD_FAILURE() << output;
    return {};
  }
  const std::string line = output.substr(at + 1, output.find('\n', at + 1) - at - 1);
  for (const std::string& c : clear) EXPECT_NE(line.find(c), std::string::npos) << line;
  EXPECT_EQ(std::count(line.begin(), line.end(), ';') + 1, static_cast<long>(clear.size()));
  return line;
}

// The fixture's six seconds give no trend; on a minute's walk whose tissue softens by 15 % a
// minute (simulate --tissue-drift) the heel's kbar is called a drift.
TEST(AnalyzeCommand, ReportsEachRegionsDriftAndNamesTheClearOnes) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  EXPECT_EQ(check_named_outputs(a.dir / "out", a.output, kDrift).rfind("drift: not estimated", 0),
            0u);

  const fs::path dir = test::scratch_dir("analyze-drift");
  int status = -1;
  std::string out = run("simulate --size 41-42 --duration 60 --seed 7 --tissue-drift -15 --out " +
                            (dir / "s.csv").string(),
                        &status);
  ASSERT_EQ(status, 0) << out;
  out = run("analyze " + (dir / "s.csv").string() + " --out " + (dir / "out").string(), &status);
  ASSERT_EQ(status, 0) << out;
  const std::string line = check_named_outputs(dir / "out", out, kDrift);
  EXPECT_NE(line.find(" heel kbar -1"), std::string::npos) << line;
}

// On a minute's walk whose right foot's tissue is 10 % stiffer and more damped (simulate
// --tissue-asymmetry), the heel's kbar is named with about that difference; on the same walk
// without it, nothing is. Each comparison's standard error holds the steps' scatter and the pair
// of insoles' own SD from the config, the heel's kbar 1.0 %.
TEST(AnalyzeCommand, ComparesTheFeetAndNamesTheClearDifferences) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  check_named_outputs(a.dir / "out", a.output, kAsymmetry);

  const fs::path dir = test::scratch_dir("analyze-asymmetry");
  for (const std::string pct : {"0", "10"}) {
    SCOPED_TRACE(pct);
    int status = -1;
    std::string out = run("simulate --size 41-42 --duration 60 --seed 7 --tissue-asymmetry " + pct +
                              " --out " + (dir / (pct + ".csv")).string(),
                          &status);
    ASSERT_EQ(status, 0) << out;
    out = run("analyze " + (dir / (pct + ".csv")).string() + " --out " + (dir / pct).string(),
              &status);
    ASSERT_EQ(status, 0) << out;
    const std::string line = check_named_outputs(dir / pct, out, kAsymmetry);
    const auto j = nlohmann::json::parse(read_all(dir / pct / "session.json"));
    const auto& heel = j.at("regions").at("heel").at("asymmetry").at("kbar");
    EXPECT_DOUBLE_EQ(heel.at("insole_pair_sd_ln_right_over_left").get<double>(), 0.01);
    EXPECT_NEAR(heel.at("se_ln_right_over_left").get<double>(),
                std::hypot(heel.at("se_steps_ln_right_over_left").get<double>(), 0.01), 1e-12);
    if (pct == "0") {
      EXPECT_EQ(line, kAsymmetry.none);
    } else {
      EXPECT_NE(line.find(" heel kbar +"), std::string::npos) << line;
      EXPECT_NEAR(heel.at("right_over_left_pct").get<double>(), 10.0, 2.0);
    }
  }
}

// The toes' cells determine no footprint, so their fits fall back to the contact ellipse; the
// summary, session.json and the report say so for them and for no other region.
TEST(AnalyzeCommand, SaysWhichRegionsWereFittedOnTheContactEllipse) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  const auto note = a.output.find("note: fitted on the contact ellipse: ");
  ASSERT_NE(note, std::string::npos) << a.output;
  const std::string line = a.output.substr(note, a.output.find('\n', note) - note);
  const auto j = nlohmann::json::parse(read_all(a.dir / "out" / "session.json"));
  const std::string html = read_all(a.dir / "out" / "report.html");
  std::size_t notes_in_report = 0;
  for (auto at = html.find("Fitted on the <b>contact ellipse</b>"); at != std::string::npos;
       at = html.find("Fitted on the <b>contact ellipse</b>", at + 1)) {
    ++notes_in_report;
  }
  for (const auto& [region, r] : j.at("regions").items()) {
    SCOPED_TRACE(region);
    const bool toe = region.rfind("toe", 0) == 0;
    const int contact = r.at("steps_with_contact").get<int>();
    EXPECT_EQ(r.at("steps_on_contact_ellipse").get<int>(), toe ? contact : 0);
    const std::string listed =
        region + " (" + std::to_string(contact) + " of " + std::to_string(contact) + " steps)";
    EXPECT_EQ(line.find(listed) != std::string::npos, toe) << line;
  }
  EXPECT_EQ(notes_in_report, 3u);
}

// --area ellipse gives the fit the seed's contact ellipse: the heel's peak contact areas differ
// from the default footprint's, and the setting is recorded.
TEST(AnalyzeCommand, AreaEllipseUsesTheContactEllipse) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  int status = -1;
  const std::string out = run("analyze " + (a.dir / "s.csv").string() + " --out " +
                                  (a.dir / "ellipse").string() + " --area ellipse",
                              &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("area ellipse"), std::string::npos) << out;
  const auto j = nlohmann::json::parse(read_all(a.dir / "ellipse" / "session.json"));
  EXPECT_EQ(j.at("settings").at("area"), "ellipse");
  const auto footprint = heel_column(a.dir / "out" / "regions.csv", 6);  // peak_area_mm2
  const auto ellipse = heel_column(a.dir / "ellipse" / "regions.csv", 6);
  ASSERT_EQ(footprint.size(), ellipse.size());
  ASSERT_FALSE(footprint.empty());
  EXPECT_NE(footprint, ellipse);
  std::string bad_status_out = run("analyze " + (a.dir / "s.csv").string() + " --out " +
                                       (a.dir / "bad").string() + " --area cells",
                                   &status);
  EXPECT_NE(status, 0) << bad_status_out;
}

// --area footprint-mean gives the fit the footprint of averaging cells: the heel's peak contact
// areas differ from the footprint's, each heel row names it, and the setting is recorded.
TEST(AnalyzeCommand, AreaFootprintMeanUsesTheCellMeanFootprint) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  int status = -1;
  const std::string out = run("analyze " + (a.dir / "s.csv").string() + " --out " +
                                  (a.dir / "mean").string() + " --area footprint-mean",
                              &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("area footprint-mean"), std::string::npos) << out;
  const auto j = nlohmann::json::parse(read_all(a.dir / "mean" / "session.json"));
  EXPECT_EQ(j.at("settings").at("area"), "footprint-mean");
  const auto footprint = heel_column(a.dir / "out" / "regions.csv", 6);  // peak_area_mm2
  const auto mean = heel_column(a.dir / "mean" / "regions.csv", 6);
  ASSERT_EQ(footprint.size(), mean.size());
  ASSERT_FALSE(footprint.empty());
  EXPECT_NE(footprint, mean);
  for (const std::string& area : heel_column(a.dir / "mean" / "regions.csv", 24)) {
    EXPECT_EQ(area, "footprint-mean");
  }
}

// How the cells read, from the session's own steps: on the centre raster the footprint is the
// one they call for; on the coverage raster footprint-mean, which the default (auto) then takes,
// and where the footprint is asked for instead the summary says to take footprint-mean. The
// raster is the simulator's, not the code's guess.
TEST(AnalyzeCommand, AreaAutoTakesTheFootprintTheCellsReadingCallsFor) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  EXPECT_NE(a.output.find("the cells read at their centres (footprint)"), std::string::npos)
      << a.output;
  EXPECT_NE(a.output.find("area footprint (auto)"), std::string::npos) << a.output;
  EXPECT_EQ(a.output.find("or auto) fits them"), std::string::npos) << a.output;
  EXPECT_EQ(a.output.find("with a crosstalk of"), std::string::npos) << a.output;
  const auto centre = nlohmann::json::parse(read_all(a.dir / "out" / "session.json"));
  EXPECT_LT(centre.at("cell_reading").at("crosstalk_coupling").get<double>(),
            CellReadingEvidence::kShownCoupling);
  EXPECT_EQ(centre.at("cell_reading").at("favoured"), "centre");
  EXPECT_GE(centre.at("cell_reading").at("frames").get<int>(), 10);
  EXPECT_LT(centre.at("cell_reading").at("centre_residual_rms_bits").get<double>(),
            centre.at("cell_reading").at("mean_residual_rms_bits").get<double>());
  EXPECT_EQ(centre.at("settings").at("area"), "footprint");
  EXPECT_EQ(centre.at("settings").at("area_auto"), true);
  EXPECT_NE(read_all(a.dir / "out" / "report.html").find("How the cells read:"), std::string::npos);
  int status = -1;
  std::string out = run("analyze " + (a.dir / "s.csv").string() + " --out " +
                            (a.dir / "footprint-centre").string() + " --area footprint",
                        &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("area footprint)"), std::string::npos) << out;
  EXPECT_EQ(settings_of(a.dir / "footprint-centre").at("area"), "footprint");
  EXPECT_EQ(settings_of(a.dir / "footprint-centre").at("area_auto"), false);

  const fs::path coverage = a.dir / "coverage.csv";
  out = run("simulate --size 37-38 --duration 6 --seed 2 --rasterisation coverage --out " +
                coverage.string(),
            &status);
  ASSERT_EQ(status, 0) << out;
  out = run("analyze " + coverage.string() + " --out " + (a.dir / "coverage").string() +
                " --area footprint",
            &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("the cells average the pressure (footprint-mean)"), std::string::npos) << out;
  EXPECT_NE(out.find("note: the footprint over-reads averaging cells"), std::string::npos) << out;
  EXPECT_EQ(nlohmann::json::parse(read_all(a.dir / "coverage" / "session.json"))
                .at("cell_reading")
                .at("favoured"),
            "mean");
  out =
      run("analyze " + coverage.string() + " --out " + (a.dir / "auto-coverage").string(), &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("area footprint-mean (auto)"), std::string::npos) << out;
  EXPECT_EQ(out.find("or auto) fits them"), std::string::npos) << out;
  EXPECT_EQ(settings_of(a.dir / "auto-coverage").at("area"), "footprint-mean");
  EXPECT_EQ(settings_of(a.dir / "auto-coverage").at("area_auto"), true);

  // The pools on footprint-mean take its chain's SDs, measured on such cells, which differ from
  // the footprint's; so do the summary and session.json.
  const Config config = load_config(default_config_path());
  const std::size_t heel = index_of(Region::Heel);
  const double mean_sd = config.pooling_footprint_mean.per_step.kbar_chain_sd_pct[heel] / 100.0;
  ASSERT_NE(mean_sd, config.pooling.per_step.kbar_chain_sd_pct[heel] / 100.0);
  EXPECT_EQ(settings_of(a.dir / "auto-coverage").at("pooling_table"), "[pooling.footprint_mean]");
  EXPECT_EQ(settings_of(a.dir / "auto-coverage").at("asymmetry_table"),
            "[asymmetry.footprint_mean]");
  EXPECT_EQ(settings_of(a.dir / "footprint-centre").at("pooling_table"), "[pooling]");
  EXPECT_NE(out.find("([pooling.footprint_mean] of the config)"), std::string::npos) << out;
  const auto heel_pool = [&](const char* dir) {
    return nlohmann::json::parse(read_all(a.dir / dir / "session.json"))
        .at("regions")
        .at("heel")
        .at("pooling");
  };
  const auto mean_pool = heel_pool("auto-coverage");
  ASSERT_TRUE(mean_pool.at("pooled").get<bool>()) << mean_pool.dump();
  EXPECT_DOUBLE_EQ(mean_pool.at("chain_sd").at("ln_kbar").get<double>(), mean_sd);
  const auto centre_pool = heel_pool("footprint-centre");
  ASSERT_TRUE(centre_pool.at("pooled").get<bool>()) << centre_pool.dump();
  EXPECT_DOUBLE_EQ(centre_pool.at("chain_sd").at("ln_kbar").get<double>(),
                   config.pooling.per_step.kbar_chain_sd_pct[heel] / 100.0);
}

TEST(AnalyzeCommand, Seed8WarnsAboutTheUndeterminedParameters) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  int status = -1;
  const std::string out = run("analyze " + (a.dir / "s.csv").string() + " --out " +
                                  (a.dir / "seed8").string() + " --fit seed8 --report",
                              &status);
  ASSERT_EQ(status, 0) << out;
  const auto warning = out.find("warning");
  ASSERT_NE(warning, std::string::npos) << out;
  const std::string line = out.substr(warning, out.find('\n', warning) - warning);
  EXPECT_NE(line.find("C_mm"), std::string::npos) << line;
  EXPECT_NE(line.find("d0_mm"), std::string::npos) << line;
  // Pooling needs the default fit's covariance, and says so.
  const auto j = nlohmann::json::parse(read_all(a.dir / "seed8" / "session.json"));
  const auto& pooling = j.at("regions").at("heel").at("pooling");
  EXPECT_FALSE(pooling.at("pooled").get<bool>());
  EXPECT_NE(pooling.at("note").get<std::string>().find("default fit"), std::string::npos);
  // The session-level fit cannot determine C either: its SE is null in the JSON, and the report
  // says so in words rather than printing inf.
  const auto& c = j.at("regions").at("heel").at("session_fit").at("parameters").at("C_mm");
  EXPECT_TRUE(c.at("se").is_null()) << c.dump();
  const std::string html = read_all(a.dir / "seed8" / "report.html");
  EXPECT_NE(html.find("(undetermined)"), std::string::npos);
  EXPECT_EQ(html.find("(inf)"), std::string::npos);
}

// --fit seed8 reproduces the seed's fit, inputs included, unless they are asked for.
TEST(AnalyzeCommand, Seed8TakesTheSeedsInputsUnlessToldOtherwise) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  EXPECT_EQ(settings_of(a.dir / "out").at("smoothing"), "none");
  EXPECT_EQ(settings_of(a.dir / "out").at("area"), "footprint");
  int status = -1;
  std::string out = run("analyze " + (a.dir / "s.csv").string() + " --out " +
                            (a.dir / "seed8-inputs").string() + " --fit seed8",
                        &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_EQ(settings_of(a.dir / "seed8-inputs").at("smoothing"), "seed");
  EXPECT_EQ(settings_of(a.dir / "seed8-inputs").at("area"), "ellipse");
  out = run("analyze " + (a.dir / "s.csv").string() + " --out " + (a.dir / "seed8-raw").string() +
                " --fit seed8 --smoothing none --area footprint",
            &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_EQ(settings_of(a.dir / "seed8-raw").at("smoothing"), "none");
  EXPECT_EQ(settings_of(a.dir / "seed8-raw").at("area"), "footprint");
}

// --end-rate second-order changes the damping fits (the rate at each contact's ends), is recorded
// and said, and is refused with the seed's smoothing, which takes the rate from its polynomial.
TEST(AnalyzeCommand, EndRateSecondOrderIsRecordedAndNeedsTheRawSeries) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  int status = -1;
  const std::string out = run("analyze " + (a.dir / "s.csv").string() + " --out " +
                                  (a.dir / "second-order").string() + " --end-rate second-order",
                              &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("end rate second-order"), std::string::npos) << out;
  EXPECT_EQ(settings_of(a.dir / "out").at("end_rate"), "two-frame");
  EXPECT_EQ(settings_of(a.dir / "second-order").at("end_rate"), "second-order");
  const auto two = heel_column(a.dir / "out" / "regions.csv", 13);  // cbar_ns_per_mm3
  const auto three = heel_column(a.dir / "second-order" / "regions.csv", 13);
  ASSERT_FALSE(two.empty());
  ASSERT_EQ(two.size(), three.size());
  EXPECT_NE(two, three);
  const std::string refused =
      run("analyze " + (a.dir / "s.csv").string() + " --out " + (a.dir / "refused").string() +
              " --end-rate second-order --smoothing seed",
          &status);
  EXPECT_NE(status, 0) << refused;
  EXPECT_NE(refused.find("--end-rate"), std::string::npos) << refused;
  EXPECT_FALSE(fs::exists(a.dir / "refused" / "regions.csv"));
}

// --free-scale fits P = pi A B per step as well: A and B in regions.csv are then fitted, the
// setting and the note say so, pooling (which needs P declared) says why it did not pool, and
// --fit seed8, which frees A and B anyway, refuses it.
TEST(AnalyzeCommand, FreeScaleFitsTheScaleAndIsRefusedWithSeed8) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  int status = -1;
  const std::string out = run("analyze " + (a.dir / "s.csv").string() + " --out " +
                                  (a.dir / "free-scale").string() + " --free-scale",
                              &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("area footprint (auto), free scale)"), std::string::npos) << out;
  EXPECT_FALSE(settings_of(a.dir / "out").at("free_scale").get<bool>());
  EXPECT_TRUE(settings_of(a.dir / "free-scale").at("free_scale").get<bool>());
  const auto j = nlohmann::json::parse(read_all(a.dir / "free-scale" / "session.json"));
  EXPECT_NE(j.at("note").get<std::string>().find("pi A B fitted (--free-scale)"),
            std::string::npos);
  const auto& heel = j.at("regions").at("heel");
  EXPECT_TRUE(heel.at("session_fit").at("parameters").at("A_mm").at("free").get<bool>());
  EXPECT_FALSE(heel.at("pooling").at("pooled").get<bool>());
  EXPECT_NE(heel.at("pooling").at("note").get<std::string>().find("P declared"), std::string::npos);
  const auto declared_a = heel_column(a.dir / "out" / "regions.csv", 7);  // A_mm
  const auto fitted_a = heel_column(a.dir / "free-scale" / "regions.csv", 7);
  ASSERT_FALSE(declared_a.empty());
  ASSERT_EQ(declared_a.size(), fitted_a.size());
  for (std::size_t i = 0; i < fitted_a.size(); ++i) EXPECT_NE(fitted_a[i], declared_a[i]) << i;

  const std::string refused =
      run("analyze " + (a.dir / "s.csv").string() + " --out " +
              (a.dir / "free-scale-seed8").string() + " --free-scale --fit seed8",
          &status);
  EXPECT_EQ(status, 2) << refused;
  EXPECT_NE(refused.find("--free-scale: applies to --fit identifiable only"), std::string::npos)
      << refused;
  EXPECT_FALSE(fs::exists(a.dir / "free-scale-seed8"));
}

// --m-per-session fits one m per region over the session and every step at it: regions.csv's m
// is then the same in every heel row, session.json says which m with its standard error, the
// summary names it, the pool takes it with its own chain SDs, and the other fits and effects in
// the model refuse it.
TEST(AnalyzeCommand, MPerSessionFitsEveryStepAtOneMPerRegion) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  int status = -1;
  const std::string out = run("analyze " + (a.dir / "s.csv").string() + " --out " +
                                  (a.dir / "m-per-session").string() + " --m-per-session",
                              &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("area footprint (auto), m per session)"), std::string::npos) << out;
  EXPECT_NE(out.find("m per session, every step fitted at it: heel "), std::string::npos) << out;
  EXPECT_FALSE(settings_of(a.dir / "out").at("m_per_session").get<bool>());
  EXPECT_TRUE(settings_of(a.dir / "m-per-session").at("m_per_session").get<bool>());
  const auto j = nlohmann::json::parse(read_all(a.dir / "m-per-session" / "session.json"));
  const auto& heel = j.at("regions").at("heel");
  const double m = heel.at("m_per_session").at("m").get<double>();
  EXPECT_GT(heel.at("m_per_session").at("se").get<double>(), 0.0);
  EXPECT_GT(heel.at("m_per_session").at("steps").get<int>(), 3);
  const auto own = heel_column(a.dir / "out" / "regions.csv", 14);  // m
  const auto shared = heel_column(a.dir / "m-per-session" / "regions.csv", 14);
  ASSERT_GT(own.size(), 3u);
  ASSERT_EQ(own.size(), shared.size());
  std::set<std::string> distinct(own.begin(), own.end());
  EXPECT_GT(distinct.size(), 1u) << "each step's own m";
  for (const std::string& v : shared) EXPECT_NEAR(std::stod(v), m, 1e-5);
  // Pooled at the shared m: the pool's m is it, its se_steps that m's own standard error, and
  // its se with [pooling.m_per_session]'s chain SD of the heel (0.06).
  const auto& pooling = heel.at("pooling");
  EXPECT_TRUE(pooling.at("pooled").get<bool>());
  EXPECT_NEAR(pooling.at("mean").at("m").get<double>(), m, 1e-9);
  const double se_m = heel.at("m_per_session").at("se").get<double>();
  EXPECT_NEAR(pooling.at("se_steps").at("m").get<double>(), se_m, 1e-9 * se_m);
  EXPECT_EQ(pooling.at("chain_sd").at("m").get<double>(), 0.06);
  EXPECT_NEAR(pooling.at("se").at("m").get<double>(), std::hypot(se_m, 0.06), 1e-9);
  EXPECT_NE(out.find("([pooling.m_per_session] of the config)"), std::string::npos) << out;
  EXPECT_TRUE(nlohmann::json::parse(read_all(a.dir / "out" / "session.json"))
                  .at("regions")
                  .at("heel")
                  .at("m_per_session")
                  .is_null());

  const std::string seed8 = run("analyze " + (a.dir / "s.csv").string() + " --out " +
                                    (a.dir / "m-seed8").string() + " --m-per-session --fit seed8",
                                &status);
  EXPECT_EQ(status, 2) << seed8;
  EXPECT_NE(seed8.find("--m-per-session: applies to the default fit only"), std::string::npos)
      << seed8;
  const std::string effects =
      run("analyze " + (a.dir / "s.csv").string() + " --out " + (a.dir / "m-effects").string() +
              " --m-per-session --effects impact_transient",
          &status);
  EXPECT_NE(status, 0) << effects;
  EXPECT_NE(effects.find("--m-per-session with effects in the model (impact_transient)"),
            std::string::npos)
      << effects;
  EXPECT_FALSE(fs::exists(a.dir / "m-seed8"));
  EXPECT_FALSE(fs::exists(a.dir / "m-effects" / "regions.csv"));
}

// A scratch copy of the shipped config in which `from`, the main file's one line of it, reads
// `to`; its directory.
fs::path shipped_config_with(const std::string& name, std::string_view from, std::string_view to) {
  const fs::path dir = test::scratch_dir(name);
  for (const char* file : {"gaitmon.toml", "insoles.toml", "tissue_seed_appendix_i.toml"}) {
    fs::copy_file(test::source_dir() / "config" / file, dir / file);
  }
  std::string config = read_all(dir / "gaitmon.toml");
  const auto at = config.find(from);
  if (at == std::string::npos || config.find(from, at + 1) != std::string::npos) {
    throw std::logic_error("the shipped config has not one \"" + std::string(from) + "\"");
  }
  config.replace(at, from.size(), to);
  test::write_text(dir / "gaitmon.toml", config);
  return dir;
}

// [model] m_per_session = true in the config does what --m-per-session does, and
// --m-per-session=false turns it off again.
TEST(AnalyzeCommand, MPerSessionComesFromTheConfigUnlessGivenOnTheCommandLine) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  const fs::path dir =
      shipped_config_with("analyze-m-config", "m_per_session = false", "m_per_session = true");
  const std::string analyze = "--config " + (dir / "gaitmon.toml").string() + " analyze " +
                              (a.dir / "s.csv").string() + " --out ";
  int status = -1;
  std::string out = run(analyze + (dir / "on").string(), &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_TRUE(settings_of(dir / "on").at("m_per_session").get<bool>());
  const auto shared = heel_column(dir / "on" / "regions.csv", 14);  // m
  ASSERT_GT(shared.size(), 3u);
  EXPECT_EQ(std::set<std::string>(shared.begin(), shared.end()).size(), 1u) << "one m";
  out = run(analyze + (dir / "off").string() + " --m-per-session=false", &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_FALSE(settings_of(dir / "off").at("m_per_session").get<bool>());
  EXPECT_EQ(read_all(dir / "off" / "regions.csv"), read_all(a.dir / "out" / "regions.csv"));
  out = run(analyze + (dir / "seed8").string() + " --fit seed8", &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("give --m-per-session=false"), std::string::npos) << out;
}

// [model] area is analyze's area where --area is not given (--fit seed8 still takes the seed's
// ellipse); --area overrides it.
TEST(AnalyzeCommand, TheAreaComesFromTheConfigUnlessGivenOnTheCommandLine) {
  const Analysed& a = analysed();
  ASSERT_EQ(a.status, 0) << a.output;
  const fs::path dir =
      shipped_config_with("analyze-area-config", R"(area = "auto")", R"(area = "footprint-mean")");
  const std::string analyze = "--config " + (dir / "gaitmon.toml").string() + " analyze " +
                              (a.dir / "s.csv").string() + " --out ";
  int status = -1;
  std::string out = run(analyze + (dir / "mean").string(), &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("area footprint-mean)"), std::string::npos) << out;
  EXPECT_EQ(settings_of(dir / "mean").at("area"), "footprint-mean");
  EXPECT_FALSE(settings_of(dir / "mean").at("area_auto").get<bool>());
  // The cells of this centre-raster session call for the footprint, which the summary says.
  EXPECT_NE(out.find("--area footprint (or auto) fits them"), std::string::npos) << out;
  out = run(analyze + (dir / "auto").string() + " --area auto", &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_EQ(settings_of(dir / "auto").at("area"), "footprint");
  EXPECT_TRUE(settings_of(dir / "auto").at("area_auto").get<bool>());
  EXPECT_EQ(read_all(dir / "auto" / "regions.csv"), read_all(a.dir / "out" / "regions.csv"));
  out = run(analyze + (dir / "seed8").string() + " --fit seed8", &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_EQ(settings_of(dir / "seed8").at("area"), "ellipse");
}

TEST(AnalyzeCommand, BadSessionFailsNamingTheLineAndLeavesNoOutput) {
  const auto dir = test::scratch_dir("analyze-bad");
  test::write_text(dir / "bad.csv", test::session_head() + test::session_row("0.0,L") +
                                        test::session_row("0.01,L", 92));
  int status = -1;
  const std::string out =
      run("analyze " + (dir / "bad.csv").string() + " --out " + (dir / "o").string() + " --report",
          &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("bad.csv:7"), std::string::npos) << out;
  for (const char* name : {"steps.csv", "regions.csv", "session.json", "report.html",
                           "steps.csv.partial", "regions.csv.partial"}) {
    EXPECT_FALSE(fs::exists(dir / "o" / name)) << name;
  }
}

// A file name that is not UTF-8 (a Latin-1 name from an older system) is written into
// session.json with U+FFFD in place of the bad byte; the analysis no longer fails at the end.
TEST(AnalyzeCommand, ASessionNameThatIsNotUtf8IsWrittenWithAReplacementCharacter) {
  const auto dir = test::scratch_dir("analyze-latin1-name");
  const fs::path session = dir / "gang\xe4nge.csv";
  fs::copy_file(analysed().dir / "s.csv", session);
  int status = -1;
  const std::string out =
      run("analyze '" + session.string() + "' --out " + (dir / "o").string(), &status);
  EXPECT_EQ(status, 0) << out;
  const auto j = nlohmann::json::parse(read_all(dir / "o" / "session.json"));
  EXPECT_NE(j.dump().find("gang\xef\xbf\xbdnge.csv"), std::string::npos);
}

// A report of an earlier run with --report would sit beside this run's CSVs and show other fits.
TEST(AnalyzeCommand, WithoutReportAnEarlierRunsReportIsRemoved) {
  const auto dir = test::scratch_dir("analyze-stale-report");
  test::write_text(dir / "o" / "report.html", "<html>an earlier run</html>\n");
  int status = -1;
  const std::string out = run(
      "analyze " + (analysed().dir / "s.csv").string() + " --out " + (dir / "o").string(), &status);
  EXPECT_EQ(status, 0) << out;
  EXPECT_FALSE(fs::exists(dir / "o" / "report.html"));
  EXPECT_TRUE(fs::exists(dir / "o" / "regions.csv"));
  EXPECT_NE(out.find("removed an earlier run's outputs from " + (dir / "o").string() +
                     ": report.html (this run writes its own, or none if it fails)"),
            std::string::npos)
      << out;
}

// A folder in an output's place, which made the last rename fail after all the work, now stops
// the run before it, when the earlier run's outputs are removed. (A rename that fails, which
// takes back the files already renamed, is tested on OutputFile itself.)
TEST(AnalyzeCommand, AFolderInAnOutputsPlaceFailsBeforeTheWorkAndLeavesNoOutput) {
  const auto dir = test::scratch_dir("analyze-rename");
  fs::create_directories(dir / "o" / "session.json" / "occupied");
  int status = -1;
  const std::string out = run(
      "analyze " + (analysed().dir / "s.csv").string() + " --out " + (dir / "o").string(), &status);
  EXPECT_NE(status, 0) << out;
  EXPECT_NE(
      out.find((dir / "o" / "session.json").string() + ": cannot remove an earlier run's output"),
      std::string::npos)
      << out;
  EXPECT_TRUE(fs::exists(dir / "o" / "session.json" / "occupied"));
  for (const char* name : {"steps.csv", "regions.csv", "steps.csv.partial", "regions.csv.partial",
                           "session.json.partial"}) {
    EXPECT_FALSE(fs::exists(dir / "o" / name)) << name;
  }
}

// The fixed tissue column's damping rate, made and fitted end to end: the truth and the settings
// name it, and the fits differ from eq 15's. (How well it recovers the truth through the
// footprint: tissue_fit_test, OnAMaterialRateSessionTheFootprintAbsorbsTheDamping.)
TEST(AnalyzeCommand, MaterialRateIsSimulatedAndFittedByName) {
  const auto dir = test::scratch_dir("analyze-material-rate");
  int status = -1;
  std::string out = run("simulate --size 37-38 --duration 6 --seed 4 --model material_rate --out " +
                            (dir / "s.csv").string(),
                        &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_EQ(nlohmann::json::parse(read_all(dir / "s.truth.json")).at("model"), "material_rate");
  std::vector<std::string> regions;
  for (const char* model : {"material_rate", "correct"}) {
    const fs::path o = dir / model;
    out = run("analyze " + (dir / "s.csv").string() + " --out " + o.string() + " --model " + model,
              &status);
    ASSERT_EQ(status, 0) << out;
    EXPECT_EQ(nlohmann::json::parse(read_all(o / "session.json")).at("settings").at("model"),
              model);
    regions.push_back(read_all(o / "regions.csv"));
  }
  EXPECT_NE(regions[0], regions[1]);
}

// `args` run with stderr on a real pseudo-terminal (stdout to /dev/null): what the terminal
// showed, and the exit status in `status`.
std::string run_on_terminal(const std::vector<std::string>& args, int* status) {
  int master = -1;
  int slave = -1;
  if (openpty(&master, &slave, nullptr, nullptr, nullptr) != 0) return "openpty failed";
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, slave, STDERR_FILENO);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
  std::vector<std::string> argv{test::gaitmon_binary().string()};
  argv.insert(argv.end(), args.begin(), args.end());
  std::vector<char*> pointers;
  for (std::string& a : argv) pointers.push_back(a.data());
  pointers.push_back(nullptr);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, pointers[0], &actions, nullptr, pointers.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  ::close(slave);
  std::string shown;
  if (rc == 0) {
    // The master reads until the child's end closes the terminal (EIO); 120 s bound a hang.
    char buffer[512];
    pollfd p{master, POLLIN, 0};
    while (::poll(&p, 1, 120'000) == 1) {
      const ssize_t n = ::read(master, buffer, sizeof buffer);
      if (n <= 0) break;
      shown.append(buffer, static_cast<std::size_t>(n));
    }
    ::kill(pid, SIGKILL);
    int wstatus = 0;
    ::waitpid(pid, &wstatus, 0);
    *status = WIFEXITED(wstatus) ? WEXITSTATUS(wstatus) : -1;
  }
  ::close(master);
  return shown;
}

// Every percentage analyze's bar drew in `shown`, in order.
std::vector<int> percents_shown(const std::string& shown) {
  std::vector<int> percents;
  const std::regex bar(R"(analyze \[[# ]{40}\] +([0-9]+)%)");
  for (auto it = std::sregex_iterator(shown.begin(), shown.end(), bar);
       it != std::sregex_iterator(); ++it) {
    percents.push_back(std::stoi((*it)[1].str()));
  }
  return percents;
}

// With a tissue effect each step's tissue is fitted with it inside, and the summary says which
// effects are inside and which on top of the baseline's fits; the per-step parameters in
// regions.csv move with it. The seed's fit cannot take an effect inside: refused before any work.
TEST(AnalyzeCommand, WithEffectsItSaysWhichAreInsideEachStepsFit) {
  const auto dir = test::scratch_dir("analyze-effects-note");
  const std::string session = (analysed().dir / "s.csv").string();
  int status = -1;
  const std::string with = run("analyze " + session + " --out " + (dir / "o").string() +
                                   " --effects impact_transient --report",
                               &status);
  ASSERT_EQ(status, 0) << with;
  EXPECT_NE(with.find("effect impact_transient:"), std::string::npos) << with;
  EXPECT_NE(with.find("note: each step's tissue parameters above and in regions.csv are fitted "
                      "with impact_transient inside its model"),
            std::string::npos)
      << with;
  EXPECT_EQ(with.find("on top of"), std::string::npos) << with;
  const auto effects_of = [&](const char* out) {
    return nlohmann::json::parse(read_all(dir / out / "session.json"))
        .at("extended_model")
        .at("effects")
        .at(0);
  };
  EXPECT_EQ(effects_of("o").at("name"), "impact_transient");
  EXPECT_EQ(effects_of("o").at("inside_tissue_fit"), true);
  // The report says so too, above the regions' parameters and forces.
  const std::string report = read_all(dir / "o" / "report.html");
  const auto said = report.find("fitted with <b>impact_transient</b> inside its model");
  EXPECT_NE(said, std::string::npos);
  EXPECT_LT(said, report.find("<section id=\"heel\">"));
  EXPECT_NE(report.find("<td>impact_transient</td><td>amplitude_n</td>"), std::string::npos);
  const std::string without =
      run("analyze " + session + " --out " + (dir / "p").string() + " --effects none --report",
          &status);
  ASSERT_EQ(status, 0) << without;
  EXPECT_EQ(without.find("note: each step"), std::string::npos) << without;
  EXPECT_NE(read_all(dir / "o" / "regions.csv"), read_all(dir / "p" / "regions.csv"));
  EXPECT_EQ(read_all(dir / "p" / "report.html").find("id=\"effects\""), std::string::npos);

  const std::string sensor = run(
      "analyze " + session + " --out " + (dir / "q").string() + " --effects thermal_drift --report",
      &status);
  ASSERT_EQ(status, 0) << sensor;
  EXPECT_NE(sensor.find("note: thermal_drift is fitted on top of the baseline's tissue "
                        "parameters, not inside each step's fit"),
            std::string::npos)
      << sensor;
  EXPECT_EQ(read_all(dir / "q" / "regions.csv"), read_all(dir / "p" / "regions.csv"));
  EXPECT_EQ(effects_of("q").at("inside_tissue_fit"), false);
  EXPECT_EQ(effects_of("q").at("undone_in_readings"), false);
  EXPECT_NE(read_all(dir / "q" / "report.html")
                .find("<b>thermal_drift</b> is fitted on top of the tissue parameters below"),
            std::string::npos);

  const std::string seed8 = run(
      "analyze " + session + " --out " + (dir / "r").string() + " --effects hysteresis --fit seed8",
      &status);
  EXPECT_NE(status, 0) << seed8;
  EXPECT_NE(seed8.find("--effects hysteresis"), std::string::npos) << seed8;
  EXPECT_NE(seed8.find("drop --fit seed8"), std::string::npos) << seed8;
  EXPECT_FALSE(fs::exists(dir / "r" / "regions.csv"));
}

// A session whose cells (averaging) creep by a gain of 0.4 at tau 1 s, the strong end of the
// simulator's default range: size 41-42, seed 117, 12 s, as DIR/c.csv.
std::string creeping_session(const fs::path& dir) {
  const std::string session = (dir / "c.csv").string();
  int status = -1;
  const std::string simulated =
      run("simulate --size 41-42 --duration 12 --seed 117 --rasterisation coverage --effect "
          "sensor_creep --effect-params '{\"gain\":0.4,\"tau_s\":1.0}' --out " +
              session,
          &status);
  if (status != 0) throw std::runtime_error("simulate failed: " + simulated);
  return session;
}

// Creep changes the shape of the readings over a region, so each step's footprint, which no map
// of the force can give back: the steps are measured again from readings with the fitted creep
// undone (creep.hpp). On cells that average, gain 0.4 and tau 1 s (the strong end of the
// simulator's range), the medians over the steps were 51-123 % off the truth as read and 0.4-5.5 %
// with the creep undone.
TEST(AnalyzeCommand, WithSensorCreepEachStepIsMeasuredFromReadingsWithTheCreepUndone) {
  const auto dir = test::scratch_dir("analyze-creep-undone");
  const std::string session = creeping_session(dir);
  int status = -1;
  const std::string as_read =
      run("analyze " + session + " --out " + (dir / "read").string() + " --effects none", &status);
  ASSERT_EQ(status, 0) << as_read;
  const std::string undone = run("analyze " + session + " --out " + (dir / "undone").string() +
                                     " --effects sensor_creep --report",
                                 &status);
  ASSERT_EQ(status, 0) << undone;
  EXPECT_NE(undone.find("note: each step above and in regions.csv is measured and fitted from "
                        "readings with the sensor creep undone (gain 0.3"),
            std::string::npos)
      << undone;
  EXPECT_EQ(undone.find("on top of"), std::string::npos) << undone;

  const auto truth = nlohmann::json::parse(read_all(dir / "c.truth.json")).at("regions");
  const auto off = [&](const char* out, const char* region, const char* param) {
    const auto j = nlohmann::json::parse(read_all(dir / out / "session.json"));
    const double median =
        j.at("regions").at(region).at("across_steps").at(param).at("median").get<double>();
    const char* truth_key = std::string_view(param) == "n" ? "n" : "kbar_n_per_mm3";
    return std::abs(median / truth.at(region).at(truth_key).get<double>() - 1.0);
  };
  for (const auto& [region, param] :
       {std::pair{"heel", "kbar_n_per_mm3"}, {"heel", "n"}, {"met1_2", "n"}, {"met3_5", "n"}}) {
    EXPECT_GT(off("read", region, param), 0.4) << region << " " << param;
    EXPECT_LT(off("undone", region, param), 0.15) << region << " " << param;
  }
  const auto total = [&](const char* out) {
    return nlohmann::json::parse(read_all(dir / out / "session.json"))
        .at("nrmse_total_pct_across_steps")
        .at("median")
        .get<double>();
  };
  EXPECT_GT(total("read"), 3.0);
  EXPECT_LT(total("undone"), 2.0);

  const auto effect = nlohmann::json::parse(read_all(dir / "undone" / "session.json"))
                          .at("extended_model")
                          .at("effects")
                          .at(0);
  EXPECT_EQ(effect.at("name"), "sensor_creep");
  EXPECT_EQ(effect.at("undone_in_readings"), true);
  EXPECT_EQ(effect.at("inside_tissue_fit"), false);
  EXPECT_NEAR(effect.at("params").at("gain").at("value").get<double>(), 0.4, 0.04);
  const std::string report = read_all(dir / "undone" / "report.html");
  EXPECT_NE(report.find("<b>sensor_creep</b> is undone in the readings"), std::string::npos);
  EXPECT_NE(report.find("<td>undone in the readings</td>"), std::string::npos);

  // An effect named beside the creep is fitted on the readings with it undone, as discrepancy
  // looks for one there. As read, stress relaxation takes up what the creep did to the footprints
  // (strength 0.33 when measured); with the creep undone it is 0.014, and the extended model's
  // NRMSE is that of those readings (6.58 -> 2.03 %).
  const auto relaxation_strength = [&](const char* out) {
    const auto j = nlohmann::json::parse(read_all(dir / out / "session.json"));
    for (const auto& e : j.at("extended_model").at("effects")) {
      if (e.at("name") == "stress_relaxation") {
        return e.at("params").at("strength").at("value").get<double>();
      }
    }
    ADD_FAILURE() << out << ": no stress_relaxation";
    return 0.0;
  };
  const std::string relaxed = run("analyze " + session + " --out " + (dir / "relaxed").string() +
                                      " --effects stress_relaxation",
                                  &status);
  ASSERT_EQ(status, 0) << relaxed;
  EXPECT_GT(relaxation_strength("relaxed"), 0.2) << relaxed;
  const std::string both = run("analyze " + session + " --out " + (dir / "both").string() +
                                   " --effects sensor_creep,stress_relaxation",
                               &status);
  ASSERT_EQ(status, 0) << both;
  EXPECT_LT(relaxation_strength("both"), 0.05) << both;
  EXPECT_NE(both.find("and stress_relaxation fitted on those readings"), std::string::npos) << both;
  const auto fit =
      nlohmann::json::parse(read_all(dir / "both" / "session.json")).at("extended_model");
  EXPECT_LT(fit.at("extended_heldout_nrmse_pct").get<double>(),
            0.5 * fit.at("baseline_heldout_nrmse_pct").get<double>())
      << fit.dump();

  // Without creep its fit here has standard errors (gain 0.14 at tau 0.06 s), but the zeros do
  // not show it (their held-out NRMSE 20 % worse with it): it stays on top, the readings as read.
  const std::string clean = (dir / "n.csv").string();
  const std::string no_creep =
      run("simulate --size 45-46 --duration 12 --seed 118 --out " + clean, &status);
  ASSERT_EQ(status, 0) << no_creep;
  const std::string kept =
      run("analyze " + clean + " --out " + (dir / "kept").string() + " --effects sensor_creep",
          &status);
  ASSERT_EQ(status, 0) << kept;
  EXPECT_NE(kept.find("note: sensor_creep is not undone in the readings: the zero channel does "
                      "not show it"),
            std::string::npos)
      << kept;
  EXPECT_EQ(kept.find("note: each step above"), std::string::npos) << kept;
  run("analyze " + clean + " --out " + (dir / "plain").string() + " --effects none", &status);
  ASSERT_EQ(status, 0);
  EXPECT_EQ(read_all(dir / "kept" / "regions.csv"), read_all(dir / "plain" / "regions.csv"));
  EXPECT_EQ(nlohmann::json::parse(read_all(dir / "kept" / "session.json"))
                .at("extended_model")
                .at("effects")
                .at(0)
                .at("undone_in_readings"),
            false);
}

// The creep analyze measures and undoes is printed as the config's [sensor_creep], ready to
// paste; under that config every frame is undone as read, so that even the ellipsoid alone
// (--effects none) measures the steps from readings without the creep, and the zeros show none
// left to undo. The progress bar covers the second reading of the session.
TEST(AnalyzeCommand, TheCreepItUndoesGoesIntoTheConfigWhichUndoesItInEveryFrame) {
  const auto dir = test::scratch_dir("analyze-creep-config");
  const std::string session = creeping_session(dir);
  int status = -1;
  const std::string shown = run(
      "analyze " + session + " --out " + (dir / "measured").string() + " --effects sensor_creep",
      &status);
  ASSERT_EQ(status, 0) << shown;
  const std::smatch lines = [&] {
    std::smatch m;
    std::regex_search(
        shown, m,
        std::regex(R"(put in the config \([^)]*gaitmon\.toml\):\r?\n)"
                   R"((\[sensor_creep\]\r?\ngain = ([0-9.]+)\r?\ntau_s = ([0-9.]+)))"));
    return m;
  }();
  ASSERT_EQ(lines.size(), 4u) << shown;
  const double gain = std::stod(lines[2].str());
  const double tau_s = std::stod(lines[3].str());
  EXPECT_NEAR(gain, 0.4, 0.04) << shown;
  EXPECT_NEAR(tau_s, 1.0, 0.25) << shown;
  const std::string bar = run_on_terminal(
      {"analyze", session, "--out", (dir / "bar").string(), "--effects", "sensor_creep"}, &status);
  ASSERT_EQ(status, 0) << bar;
  const std::vector<int> percents = percents_shown(bar);
  EXPECT_TRUE(std::is_sorted(percents.begin(), percents.end())) << bar;
  EXPECT_TRUE(std::any_of(percents.begin(), percents.end(), [](int p) { return p > 65 && p < 95; }))
      << "the steps measured again from the readings with the creep undone: " << bar;

  // The keys below the section's comments, as a user pastes them.
  std::string pasted = lines[1].str();
  std::erase(pasted, '\r');
  pasted.erase(0, pasted.find('\n') + 1);
  const fs::path config =
      shipped_config_with("analyze-creep-config-file", "gain = 0\ntau_s = 1.0", pasted);
  const std::string with_config = "--config " + (config / "gaitmon.toml").string() + " ";
  const std::string plain = run(
      with_config + "analyze " + session + " --out " + (dir / "plain").string() + " --effects none",
      &status);
  ASSERT_EQ(status, 0) << plain;
  const auto settings = settings_of(dir / "plain").at("sensor_creep_of_config");
  EXPECT_DOUBLE_EQ(settings.at("gain").get<double>(), gain);
  const auto truth = nlohmann::json::parse(read_all(dir / "c.truth.json")).at("regions");
  const auto plain_json = nlohmann::json::parse(read_all(dir / "plain" / "session.json"));
  for (const char* region : {"heel", "met1_2", "met3_5"}) {
    const double n =
        plain_json.at("regions").at(region).at("across_steps").at("n").at("median").get<double>();
    EXPECT_NEAR(n / truth.at(region).at("n").get<double>(), 1.0, 0.15) << region;
  }
  EXPECT_LT(plain_json.at("nrmse_total_pct_across_steps").at("median").get<double>(), 2.0);

  const std::string again = run(with_config + "analyze " + session + " --out " +
                                    (dir / "again").string() + " --effects sensor_creep",
                                &status);
  ASSERT_EQ(status, 0) << again;
  EXPECT_EQ(again.find("put in the config"), std::string::npos) << again;
  const auto left = nlohmann::json::parse(read_all(dir / "again" / "session.json"))
                        .at("extended_model")
                        .at("effects")
                        .at(0);
  EXPECT_LT(left.at("params").at("gain").at("value").get<double>(), 0.05) << again;
}

// The bar covers the whole job, the extended model's fit and the session-level fits too: it
// ended at 95 % before.
TEST(AnalyzeCommand, ProgressBarOnATerminalRisesToAHundredPercent) {
  const auto dir = test::scratch_dir("analyze-progress");
  int status = -1;
  const std::string shown =
      run_on_terminal({"analyze", (analysed().dir / "s.csv").string(), "--out",
                       (dir / "o").string(), "--effects", "impact_transient"},
                      &status);
  EXPECT_EQ(status, 0) << shown;
  const std::vector<int> percents = percents_shown(shown);
  ASSERT_GE(percents.size(), 3u) << shown;
  EXPECT_TRUE(std::is_sorted(percents.begin(), percents.end())) << shown;
  EXPECT_EQ(percents.back(), 100) << shown;
  EXPECT_TRUE(fs::exists(dir / "o" / "session.json"));
}

}  // namespace
}  // namespace gaitmon
