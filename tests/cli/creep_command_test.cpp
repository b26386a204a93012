// `gaitmon creep` as a lab engineer runs it: recordings of one pair agree on the creep the
// simulator gave them and print the section to paste, under which little is left; recordings of
// two pairs, and the three real recordings, do not; the standard errors cover the spread of ten
// walks; creep.json and creep.html say the same; bad input is a clear error.
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <stdexcept>
#include <string>
#include <vector>

#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;

using test::run_gaitmon;

// A 20-s walk on insoles of `size` whose cells creep by `gain` at `tau_s`, as DIR/NAME.
std::string walk(const fs::path& dir, const std::string& name, int seed, double gain, double tau_s,
                 const std::string& size = "41-42", const std::string& options = "") {
  const std::string session = (dir / name).string();
  int status = -1;
  const std::string out =
      run_gaitmon("simulate --size " + size + " --duration 20 --seed " + std::to_string(seed) +
                      " --effect sensor_creep --effect-params '{\"gain\":" + std::to_string(gain) +
                      ",\"tau_s\":" + std::to_string(tau_s) + "}' --out " + session + options,
                  &status);
  if (status != 0) throw std::runtime_error("simulate failed: " + out);
  return session;
}

// One row of the table: the recording's fitted gain, its zero channel's held-out NRMSE without and
// with the creep, and whether the zeros show it.
struct Row {
  double gain = 0.0;
  double zero_before_pct = 0.0;
  double zero_after_pct = 0.0;
  bool shown = false;
};

std::map<std::string, Row> rows_of(const std::string& out) {
  std::map<std::string, Row> rows;
  const std::regex row(
      R"((\S+\.csv) +[0-9]+ +([0-9.e-]+) (?:\+- \S+|\(no SE\)) +[0-9.e-]+ (?:\+- \S+|\(no SE\)) +)"
      R"(([0-9.]+) -> ([0-9.]+) % +(yes|no))");
  for (auto it = std::sregex_iterator(out.begin(), out.end(), row); it != std::sregex_iterator();
       ++it) {
    const std::smatch& m = *it;
    rows[m[1].str()] = {std::stod(m[2].str()), std::stod(m[3].str()), std::stod(m[4].str()),
                        m[5].str() == "yes"};
  }
  return rows;
}

// Three walks of one pair (gain 0.3, tau 2 s): each shows the creep, their spread is within their
// errors (p 0.04: one walk fits 0.37 +- 0.025), and the mean goes into the config. Under it each
// walk's zeros, before any creep is fitted, lose most of what that walk's own creep took off as
// read (89-92 %), and what creep a walk still shows on top is under a quarter of the pasted one
// (0.059 at 1.1 s). A fourth walk on a pair that creeps by 0.15 at 0.5 s makes them disagree, and
// nothing is printed to paste.
TEST(CreepCommand, WalksOfOnePairAgreeAndThoseOfTwoPairsDoNot) {
  const auto dir = test::scratch_dir("creep-command");
  const std::string one_pair = walk(dir, "a.csv", 7, 0.3, 2.0) + " " +
                               walk(dir, "b.csv", 8, 0.3, 2.0) + " " +
                               walk(dir, "c.csv", 9, 0.3, 2.0);
  int status = -1;
  const fs::path out_dir = dir / "out";
  const std::string agreed =
      run_gaitmon("creep " + one_pair + " --out " + out_dir.string() + " --report", &status);
  ASSERT_EQ(status, 0) << agreed;
  const std::map<std::string, Row> as_read = rows_of(agreed);
  ASSERT_EQ(as_read.size(), 3u) << agreed;
  for (const auto& [name, row] : as_read) {
    EXPECT_TRUE(row.shown) << name;
    EXPECT_NEAR(row.gain, 0.3, 0.1) << name;
  }
  EXPECT_NE(agreed.find("they agree on one creep"), std::string::npos) << agreed;
  std::smatch section;
  ASSERT_TRUE(std::regex_search(
      agreed, section, std::regex(R"(\[sensor_creep\]\ngain = ([0-9.]+)\ntau_s = ([0-9.]+))")))
      << agreed;
  const double pasted_gain = std::stod(section[1].str());
  EXPECT_NEAR(pasted_gain, 0.3, 0.03) << agreed;
  EXPECT_NEAR(std::stod(section[2].str()), 2.0, 0.3) << agreed;
  // creep.json holds what stdout says, and creep.html draws each walk in both panels.
  const nlohmann::json found = nlohmann::json::parse(test::read_text(out_dir / "creep.json"));
  EXPECT_EQ(found["verdict"], "agree");
  ASSERT_EQ(found["recordings"].size(), 3u);
  for (const nlohmann::json& r : found["recordings"]) {
    EXPECT_TRUE(r["shows_creep"].get<bool>()) << r;
    EXPECT_NEAR(r["gain"].get<double>(), as_read.at(fs::path(r["session"]).filename()).gain, 1e-3)
        << r;
    // The simulator draws each cell's dc bias from 0-2 bits: some loaded cells rest at 0.
    EXPECT_GT(r["loaded_cells_at_zero_pct"].get<double>(), 0.0) << r;
  }
  EXPECT_EQ(found["agreement"]["degrees_of_freedom"], 2);
  EXPECT_NEAR(found["sensor_creep_to_paste"]["gain"].get<double>(), pasted_gain, 1e-4);
  const std::string page = test::read_text(out_dir / "creep.html");
  EXPECT_EQ(test::count(page, "class=\"estimate\""), 6u);
  EXPECT_EQ(test::count(page, "class=\"mean\""), 2u);
  EXPECT_NE(page.find("they agree on one creep"), std::string::npos);

  const fs::path config_dir = test::scratch_dir("creep-command-config");
  for (const char* file : {"gaitmon.toml", "insoles.toml", "tissue_seed_appendix_i.toml"}) {
    fs::copy_file(test::source_dir() / "config" / file, config_dir / file);
  }
  std::string config = test::read_text(config_dir / "gaitmon.toml");
  const std::string shipped = "\ngain = 0\ntau_s = 1.0\n";
  ASSERT_NE(config.find(shipped), std::string::npos);
  config.replace(config.find(shipped), shipped.size(),
                 "\ngain = " + section[1].str() + "\ntau_s = " + section[2].str() + "\n");
  test::write_text(config_dir / "gaitmon.toml", config);
  const std::string left = run_gaitmon(
      "--config " + (config_dir / "gaitmon.toml").string() + " creep " + one_pair, &status);
  ASSERT_EQ(status, 0) << left;
  EXPECT_NE(left.find("on top of the config's [sensor_creep] (gain " + section[1].str()),
            std::string::npos)
      << left;
  const std::map<std::string, Row> undone = rows_of(left);
  ASSERT_EQ(undone.size(), 3u) << left;
  for (const auto& [name, row] : undone) {
    const Row& read = as_read.at(name);
    EXPECT_LT(row.zero_before_pct,
              read.zero_before_pct - 0.8 * (read.zero_before_pct - read.zero_after_pct))
        << name << "\n"
        << left;
    if (row.shown) {
      EXPECT_LT(row.gain, 0.25 * pasted_gain) << name << "\n" << left;
    }
  }

  const std::string two_pairs =
      run_gaitmon("creep " + one_pair + " " + walk(dir, "other.csv", 10, 0.15, 0.5) + " --out " +
                      out_dir.string(),
                  &status);
  ASSERT_EQ(status, 0) << two_pairs;
  EXPECT_NE(two_pairs.find("they disagree"), std::string::npos) << two_pairs;
  EXPECT_EQ(two_pairs.find("[sensor_creep]"), std::string::npos) << two_pairs;
  const nlohmann::json disagreed = nlohmann::json::parse(test::read_text(out_dir / "creep.json"));
  EXPECT_EQ(disagreed["verdict"], "disagree");
  EXPECT_FALSE(disagreed["agreement"]["agree"].get<bool>());
  EXPECT_TRUE(disagreed["sensor_creep_to_paste"].is_null());
  // Without --report this run writes no page, and the earlier run's is gone.
  EXPECT_FALSE(fs::exists(out_dir / "creep.html"));

  const std::string alone =
      run_gaitmon("creep " + (dir / "a.csv").string() + " --out " + out_dir.string(), &status);
  ASSERT_EQ(status, 0) << alone;
  EXPECT_NE(alone.find("one recording shows a creep"), std::string::npos) << alone;
  const nlohmann::json one = nlohmann::json::parse(test::read_text(out_dir / "creep.json"));
  EXPECT_EQ(one["verdict"], "one_shows");
  EXPECT_TRUE(one["agreement"].is_null());
  EXPECT_EQ(alone.find("[sensor_creep]"), std::string::npos) << alone;
}

// The three real recordings each show a creep (gains 0.003-0.08), far apart against their
// errors: three subjects, perhaps three pairs, not one creep.
TEST(CreepCommand, TheRealRecordingsDisagree) {
  if (test::kSanitized) {
    GTEST_SKIP() << "five and a half minutes of real walking take too long under the sanitizers; "
                    "the command's code runs under them in "
                    "WalksOfOnePairAgreeAndThoseOfTwoPairsDoNot";
  }
  const fs::path real = test::shared_dir() / "real-data" / "gaitpdb";
  std::string sessions;
  for (const char* name : {"GaCo01_01", "JuPt01_01", "SiCo01_01"}) {
    sessions += " " + (real / ("gaitpdb_" + std::string(name) + ".csv")).string();
  }
  int status = -1;
  const std::string out = run_gaitmon("creep" + sessions, &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("the 3 recordings that show it"), std::string::npos) << out;
  EXPECT_NE(out.find("they disagree"), std::string::npos) << out;
}

// The agreement test is only as good as the standard errors it weighs: over ten walks of one pair
// their spread must look like those errors, neither wider (chi-square above 23.6, the 99.5th
// percentile on 9 degrees of freedom: too small errors would call one pair two) nor much narrower
// (below 1.73, the 0.5th). Size 41-42 with gain 0.3 at tau 2 s (seeds 11-20): gain 3.2, tau 6.5.
// Size 45-46 with a fast creep, gain 0.4 at tau 0.5 s (seeds 31-40): 14.7 and 19.5; with the
// curvature's errors alone 22.3 and 41.5, and the walks were called two pairs.
TEST(CreepCommand, TheStandardErrorsCoverTheSpreadOfTenWalksOfOnePair) {
  if (test::kSanitized) {
    GTEST_SKIP()
        << "twenty walks take too long under the sanitizers; the command's code, its "
           "errors included, runs under them in WalksOfOnePairAgreeAndThoseOfTwoPairsDoNot";
  }
  struct Pair {
    std::string size;
    int first_seed;
    double gain, tau_s;
  };
  for (const Pair& pair : {Pair{"41-42", 11, 0.3, 2.0}, Pair{"45-46", 31, 0.4, 0.5}}) {
    const auto dir = test::scratch_dir("creep-command-ten-" + pair.size);
    std::string walks;
    for (int seed = pair.first_seed; seed < pair.first_seed + 10; ++seed) {
      walks += " " + walk(dir, "w" + std::to_string(seed) + ".csv", seed, pair.gain, pair.tau_s,
                          pair.size);
    }
    int status = -1;
    const std::string out =
        run_gaitmon("creep" + walks + " --out " + (dir / "out").string(), &status);
    ASSERT_EQ(status, 0) << out;
    const nlohmann::json found = nlohmann::json::parse(test::read_text(dir / "out" / "creep.json"));
    ASSERT_FALSE(found["agreement"].is_null()) << out;
    ASSERT_EQ(found["agreement"]["degrees_of_freedom"], 9) << out;
    for (const char* chi2 : {"gain_chi2", "tau_chi2"}) {
      EXPECT_GT(found["agreement"][chi2].get<double>(), 1.73) << chi2 << "\n" << out;
      EXPECT_LT(found["agreement"][chi2].get<double>(), 23.6) << chi2 << "\n" << out;
    }
    EXPECT_EQ(found["verdict"], "agree") << out;
  }
}

// Where no cell's zero reading is clipped at 0, ten walks of one pair give the creep without a
// bias: size 37-38, gain 0.2 at tau 1 s, seeds 31-40, every cell's dc bias 3-5 bits, over six
// times the noise's SD (measured: gain 0.2003 +- 0.0019, tau 1.018 +- 0.018 s). With the
// simulator's default bias of 0-2 bits, where a third of the cells read their noise clipped at 0
// in the swing, the same walks gave 0.194 +- 0.002, and with no bias 0.183 (README, "Sensor creep
// of the insoles").
TEST(CreepCommand, WalksWhoseZerosClearTheFloorGiveTheCreepWithoutABias) {
  if (test::kSanitized) {
    GTEST_SKIP()
        << "ten walks take too long under the sanitizers; the command's code runs under them in "
           "WalksOfOnePairAgreeAndThoseOfTwoPairsDoNot";
  }
  const auto dir = test::scratch_dir("creep-command-above-floor");
  std::string walks;
  for (int seed = 31; seed <= 40; ++seed) {
    walks += " " + walk(dir, "w" + std::to_string(seed) + ".csv", seed, 0.2, 1.0, "37-38",
                        " --min-bias 3 --max-bias 5");
  }
  int status = -1;
  const std::string out =
      run_gaitmon("creep" + walks + " --out " + (dir / "out").string(), &status);
  ASSERT_EQ(status, 0) << out;
  const nlohmann::json found = nlohmann::json::parse(test::read_text(dir / "out" / "creep.json"));
  ASSERT_EQ(found["verdict"], "agree") << out;
  for (const nlohmann::json& r : found["recordings"]) {
    EXPECT_EQ(r["loaded_cells_at_zero_pct"].get<double>(), 0.0) << r;
  }
  EXPECT_EQ(out.find("rest at 0"), std::string::npos) << out;
  const nlohmann::json& mean = found["agreement"]["weighted_mean"];
  EXPECT_NEAR(mean["gain"].get<double>(), 0.2, 3.0 * mean["gain_se"].get<double>()) << out;
  EXPECT_NEAR(mean["tau_s"].get<double>(), 1.0, 3.0 * mean["tau_se_s"].get<double>()) << out;
  EXPECT_LT(mean["gain_se"].get<double>(), 0.005) << out;
}

TEST(CreepCommand, BadInputIsAClearErrorNamingIt) {
  const auto dir = test::scratch_dir("creep-command-bad");
  const std::string a = walk(dir, "a.csv", 7, 0.3, 2.0);
  int status = -1;
  std::string out = run_gaitmon("creep " + a + " " + a, &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("is given twice"), std::string::npos) << out;

  out = run_gaitmon("creep " + a + " " + (dir / "missing.csv").string(), &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("missing.csv"), std::string::npos) << out;

  // Two steps a foot: too few to hold the creep out over five folds.
  const std::string short_walk = (dir / "short.csv").string();
  run_gaitmon("simulate --size 41-42 --duration 3 --seed 7 --out " + short_walk, &status);
  ASSERT_EQ(status, 0);
  // An earlier run's creep.json is removed before the work, so a failed run leaves none.
  const fs::path out_dir = dir / "out";
  test::write_text(out_dir / "creep.json", "{}\n");
  out = run_gaitmon("creep " + a + " " + short_walk + " --out " + out_dir.string(), &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("short.csv"), std::string::npos) << out;
  EXPECT_NE(out.find("need at least 5"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(out_dir / "creep.json"));
  EXPECT_FALSE(fs::exists(out_dir / "creep.json.partial"));

  out = run_gaitmon("creep " + a + " --report", &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("--report requires --out"), std::string::npos) << out;

  out = run_gaitmon("creep " + a + " --out " + a, &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("--out"), std::string::npos) << out;

  // A recording kept in the output folder under an output's name is never removed as one.
  const fs::path kept = out_dir / "creep.json";
  fs::copy_file(a, kept);
  out = run_gaitmon("creep " + a + " " + kept.string() + " --out " + out_dir.string(), &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("is the file this command reads"), std::string::npos) << out;
  EXPECT_TRUE(fs::exists(kept));

  out = run_gaitmon("creep " + a + " --min-p 1.5", &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("--min-p"), std::string::npos) << out;
}

}  // namespace
}  // namespace gaitmon
