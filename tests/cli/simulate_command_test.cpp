// `gaitmon simulate` as a user runs it: --param sets one region's tissue truth, --effect and
// --effect-params add hidden effects, and every malformed value is a usage error (exit 2) that
// quotes what was given and writes nothing.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <span>
#include <string>

#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;

nlohmann::json truth_of(const fs::path& session) {
  std::ifstream in(fs::path(session).replace_extension(".truth.json"));
  return nlohmann::json::parse(in);
}

std::string simulate(const fs::path& out, const std::string& args, int* status) {
  std::string output;
  *status =
      test::run_command(test::gaitmon_binary().string() + " simulate --duration 2 --seed 5 --out " +
                            out.string() + " " + args,
                        &output);
  return output;
}

TEST(SimulateCommand, ParamSetsOneRegionsTissueAndKeepsTheRest) {
  const auto dir = test::scratch_dir("simulate-param");
  int status = -1;
  std::string out = simulate(dir / "plain.csv", "", &status);
  ASSERT_EQ(status, 0) << out;
  out = simulate(dir / "param.csv", "--param heel.kbar_n_per_mm3=0.2 --param heel.n=0.4", &status);
  ASSERT_EQ(status, 0) << out;
  const auto plain = truth_of(dir / "plain.csv").at("regions");
  const auto param = truth_of(dir / "param.csv").at("regions");
  EXPECT_EQ(param.at("heel").at("kbar_n_per_mm3"), 0.2);
  EXPECT_EQ(param.at("heel").at("n"), 0.4);
  // The heel's other fields stay Appendix I's means for size 37-38.
  EXPECT_EQ(param.at("heel").at("C_mm"), 69.9);
  EXPECT_EQ(param.at("heel").at("d0_mm"), 16.4);
  EXPECT_EQ(param.at("heel").at("cbar_ns_per_mm3"), 0.011);
  EXPECT_EQ(plain.at("heel").at("kbar_n_per_mm3"), 0.117);
  for (const char* region : {"midfoot_posterior", "met1_2", "toes3_5"}) {
    EXPECT_EQ(param.at(region), plain.at(region)) << region;
  }
}

TEST(SimulateCommand, AMalformedParamIsAUsageErrorThatNamesItAndWritesNothing) {
  const auto dir = test::scratch_dir("simulate-bad-param");
  const struct {
    const char* param;
    const char* says;
  } cases[] = {
      {"heel.kbar_n_per_mm3", "'heel.kbar_n_per_mm3': expected REGION.FIELD=VALUE"},
      {"kbar_n_per_mm3=0.2", "'kbar_n_per_mm3=0.2': expected REGION.FIELD=VALUE"},
      {"ball.n=0.3", "'ball.n=0.3': unknown region (heel, midfoot_posterior"},
      {"heel.stiffness=0.2", "'heel.stiffness=0.2': unknown field 'stiffness' (A_mm, B_mm"},
      {"heel.n=abc", "'heel.n=abc': the value is not a number"},
      {"heel.n=0.3x", "'heel.n=0.3x': the value is not a number"},
      {"heel.n=-0.3", "'heel.n=-0.3': must be > 0"},
      {"heel.n=0", "'heel.n=0': must be > 0"},
      {"heel.kbar_n_per_mm3=inf", "'heel.kbar_n_per_mm3=inf': must be finite"},
      {"heel.A_mm=1e400", "'heel.A_mm=1e400': the value is not a number"},
  };
  for (const auto& c : cases) {
    int status = -1;
    const std::string out = simulate(dir / "s.csv", std::string("--param ") + c.param, &status);
    EXPECT_EQ(status, 2) << c.param << "\n" << out;
    EXPECT_NE(out.find(std::string("--param: ") + c.says), std::string::npos) << out;
    EXPECT_FALSE(fs::exists(dir / "s.csv")) << c.param;
    EXPECT_FALSE(fs::exists(dir / "s.truth.json")) << c.param;
  }
}

// Publishing renames a finished file over the output's name, which would replace a device, a
// pipe or a link with a regular file: such outputs are refused before anything is simulated,
// and so is a truth file that is the session file.
TEST(SimulateCommand, AnOutputThatIsNotARegularFileIsRefusedAndLeftAlone) {
  const auto dir = test::scratch_dir("simulate-special-out");
  const fs::path fifo = dir / "pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const fs::path link = dir / "link.csv";
  test::write_text(dir / "target.csv", "kept\n");
  fs::create_symlink(dir / "target.csv", link);
  fs::create_directories(dir / "folder");
  const struct {
    std::string args;
    std::string says;
  } cases[] = {
      {(fifo).string(), "--out: " + fifo.string() + " exists and is not a regular file"},
      {(link).string(), "--out: " + link.string() + " exists and is not a regular file"},
      {(dir / "folder").string(), "--out: " + (dir / "folder").string() + " is a directory"},
      {(dir / "s.csv").string() + " --truth " + fifo.string(),
       "--truth: " + fifo.string() + " exists and is not a regular file"},
      {(dir / "s.csv").string() + " --truth " + (dir / "s.csv").string(),
       "--truth: is the same file as --out"},
  };
  for (const auto& c : cases) {
    int status = -1;
    const std::string out = simulate(c.args, "", &status);
    EXPECT_EQ(status, 2) << c.args << "\n" << out;
    EXPECT_NE(out.find(c.says), std::string::npos) << out;
  }
  EXPECT_TRUE(fs::is_fifo(fs::symlink_status(fifo)));
  EXPECT_TRUE(fs::is_symlink(fs::symlink_status(link)));
  EXPECT_FALSE(fs::exists(dir / "s.csv"));
  std::ifstream kept(dir / "target.csv");
  std::string line;
  std::getline(kept, line);
  EXPECT_EQ(line, "kept");
}

TEST(SimulateCommand, AFailedRunLeavesNeitherFileUnderItsFinalName) {
  const auto dir = test::scratch_dir("simulate-fails");
  // (A rename that fails after the session was written, which takes back the file already
  // renamed, is tested on OutputFile itself: a folder in the truth's place, which made it fail
  // here, is now refused before anything is written.)
  // Cut short by the file size limit (SIGXFSZ ignored, so the write fails instead).
  const std::string limited = "(trap '' XFSZ; ulimit -f 64; " + test::gaitmon_binary().string() +
                              " simulate --duration 10 --out " + (dir / "big.csv").string() + ")";
  std::string output;
  EXPECT_NE(test::run_command(limited, &output), 0) << output;
  EXPECT_FALSE(fs::exists(dir / "big.csv"));
  EXPECT_FALSE(fs::exists(dir / "big.truth.json"));
  EXPECT_FALSE(fs::exists(dir / "big.csv.partial"));
}

TEST(SimulateCommand, EffectParamsAreCheckedAndRecordedInTheTruth) {
  const auto dir = test::scratch_dir("simulate-effects");
  const struct {
    const char* args;
    const char* says;
  } bad[] = {
      {"--effect ghosting", "--effect: unknown simulation effect 'ghosting'"},
      {"--effect hysteresis --effect sensor_creep --effect hysteresis",
       "--effect: 'hysteresis' is given twice"},
      {R"(--effect hysteresis --effect-params '{"strength":')", "--effect-params: not valid JSON"},
      {R"(--effect hysteresis --effect-params '{"strength":1e999}')",
       "--effect-params: not valid JSON"},
      {"--effect hysteresis --effect-params '[0.1]'", "--effect-params: expected a JSON object"},
      {R"(--effect hysteresis --effect-params '{"tau_s":1}')", "unknown parameter 'tau_s'"},
      {R"(--effect hysteresis --effect-params '{"strength":"high"}')",
       "--effect-params: 'strength' of 'hysteresis' must be a number"},
      {R"(--effect hysteresis --effect-params '{"strength":5}')",
       "parameter 'strength' = 5.000000 is outside [0.030000, 0.300000]"},
      {R"(--effect hysteresis --effect sensor_creep --effect-params '{"gain":0.1}')",
       "--effect-params: with a flat object give exactly one --effect"},
      {R"(--effect hysteresis --effect-params '{"sensor_creep":{"gain":0.1}}')",
       "--effect-params: 'sensor_creep' is not one of the --effect"},
      {R"(--effect hysteresis --effect sensor_creep --effect-params '{"hysteresis":{},"sensor_creep":[1]}')",
       "--effect-params: the parameters of 'sensor_creep' must be a JSON object"},
  };
  for (const auto& c : bad) {
    int status = -1;
    const std::string out = simulate(dir / "bad.csv", c.args, &status);
    EXPECT_EQ(status, 2) << c.args << "\n" << out;
    EXPECT_NE(out.find(c.says), std::string::npos) << c.args << "\n" << out;
    EXPECT_FALSE(fs::exists(dir / "bad.csv")) << c.args;
  }

  int status = -1;
  const std::string out = simulate(dir / "s.csv",
                                   "--effect hysteresis --effect sensor_creep --effect-params "
                                   R"('{"sensor_creep":{"gain":0.1}}')",
                                   &status);
  ASSERT_EQ(status, 0) << out;
  const auto effects = truth_of(dir / "s.csv").at("options").at("effects");
  ASSERT_EQ(effects.size(), 2u);
  EXPECT_EQ(effects[1]["params"]["gain"], 0.1);
  EXPECT_EQ(effects[1]["params"]["tau_s"], 1.5);      // the default
  EXPECT_EQ(effects[0]["params"]["strength"], 0.12);  // the default
}

// The config's [sensor_creep] is the creep of the insoles it describes: simulated cells creep so,
// in the effects' order (after hysteresis, before crosstalk), and say so, unless --effect
// sensor_creep gives a creep of the run's own.
TEST(SimulateCommand, CellsCreepAsTheConfigsSensorCreepSays) {
  const auto dir = test::scratch_dir("simulate-config-creep");
  for (const char* file : {"gaitmon.toml", "insoles.toml", "tissue_seed_appendix_i.toml"}) {
    fs::copy_file(test::source_dir() / "config" / file, dir / file);
  }
  std::string config = test::read_text(dir / "gaitmon.toml");
  const std::string shipped = "\ngain = 0\ntau_s = 1.0\n";
  ASSERT_NE(config.find(shipped), std::string::npos);
  config.replace(config.find(shipped), shipped.size(), "\ngain = 0.25\ntau_s = 3\n");
  test::write_text(dir / "gaitmon.toml", config);
  const std::string with_config = "--config " + (dir / "gaitmon.toml").string() + " ";

  int status = -1;
  std::string out =
      simulate(dir / "c.csv", with_config + "--effect hysteresis --effect crosstalk", &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("the cells creep as the config's [sensor_creep] says: gain 0.25, tau 3 s"),
            std::string::npos)
      << out;
  auto effects = truth_of(dir / "c.csv").at("options").at("effects");
  ASSERT_EQ(effects.size(), 3u) << effects.dump();
  EXPECT_EQ(effects[0]["name"], "hysteresis");
  EXPECT_EQ(effects[1]["name"], "sensor_creep");
  EXPECT_EQ(effects[1]["params"]["gain"], 0.25);
  EXPECT_EQ(effects[1]["params"]["tau_s"], 3.0);
  EXPECT_EQ(effects[2]["name"], "crosstalk");

  out = simulate(dir / "own.csv",
                 with_config + R"(--effect sensor_creep --effect-params '{"gain":0.1}')", &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_EQ(out.find("[sensor_creep]"), std::string::npos) << out;
  effects = truth_of(dir / "own.csv").at("options").at("effects");
  ASSERT_EQ(effects.size(), 1u) << effects.dump();
  EXPECT_EQ(effects[0]["params"]["gain"], 0.1);

  out = simulate(dir / "plain.csv", "", &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_TRUE(truth_of(dir / "plain.csv").at("options").at("effects").empty());
}

struct UsageError {
  const char* args;
  const char* says;
};

// Each is refused with exit code 2 and its message, and no session is written.
void expect_usage_errors(const fs::path& dir, std::span<const UsageError> cases) {
  for (const UsageError& c : cases) {
    int status = -1;
    const std::string out = simulate(dir / "bad.csv", c.args, &status);
    EXPECT_EQ(status, 2) << c.args << "\n" << out;
    EXPECT_NE(out.find(c.says), std::string::npos) << c.args << "\n" << out;
    EXPECT_FALSE(fs::exists(dir / "bad.csv")) << c.args;
  }
}

// An empty --effect-params was taken for the defaults, and of two equal keys nlohmann::json kept
// the last without a word; a subject the session header cannot hold failed only at the writing.
TEST(SimulateCommand, EmptyOrDuplicateEffectParamsAndAMultiLineSubjectAreUsageErrors) {
  const UsageError bad[] = {
      {"--effect hysteresis --effect-params ''", "--effect-params: is empty"},
      {R"(--effect hysteresis --effect-params '{"strength":0.1,"strength":0.2}')",
       "--effect-params: key 'strength' is given twice"},
      {R"(--effect hysteresis --effect sensor_creep --effect-params '{"sensor_creep":{"gain":0.1,"tau_s":1,"gain":0.2}}')",
       "--effect-params: key 'gain' is given twice"},
      {R"(--effect hysteresis --effect sensor_creep --effect-params '{"hysteresis":{},"hysteresis":{}}')",
       "--effect-params: key 'hysteresis' is given twice"},
      {"--subject 'two\nlines'", "--subject: contains a line break"},
      {"--subject ' padded'", "--subject: starts or ends with a blank"},
  };
  expect_usage_errors(test::scratch_dir("simulate-bad-text"), bad);
}

// --min-bias and --max-bias are each within range on their own; together the least must not be
// more than the most, which only the pair can say.
TEST(SimulateCommand, ALeastBiasAboveTheMostIsAUsageError) {
  const auto dir = test::scratch_dir("simulate-bias");
  const UsageError bad[] = {
      {"--min-bias 3", "--min-bias: 3 is more than --max-bias (2)"},
      {"--min-bias 4 --max-bias 3", "--min-bias: 4 is more than --max-bias (3)"},
  };
  expect_usage_errors(dir, bad);
  int status = -1;
  const std::string out = simulate(dir / "ok.csv", "--min-bias 2 --max-bias 2", &status);
  ASSERT_EQ(status, 0) << out;
  const nlohmann::json truth = nlohmann::json::parse(test::read_text(dir / "ok.truth.json"));
  for (const auto& [foot, bias] : truth.at("dc_bias_bits").items()) {
    for (const auto& b : bias) EXPECT_EQ(b.get<int>(), 2) << foot;
  }
}

}  // namespace
}  // namespace gaitmon
