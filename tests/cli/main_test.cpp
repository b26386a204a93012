// The gaitmon program end to end: simulate, segment, help and its errors on bad input.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "test_support.hpp"

namespace gaitmon {
namespace {

using test::run_gaitmon;

std::string first_line(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  return line;
}

TEST(Cli, HelpListsTheSubcommands) {
  int status = -1;
  const std::string out = run_gaitmon("--help", &status);
  EXPECT_EQ(status, 0);
  EXPECT_NE(out.find("simulate"), std::string::npos) << out;
  EXPECT_NE(out.find("segment"), std::string::npos) << out;
}

TEST(Cli, SimulateThenSegmentWritesTheDocumentedFiles) {
  const auto dir = test::scratch_dir("cli-sim");
  int status = -1;
  std::string out = run_gaitmon(
      "simulate --size 39-40 --duration 12 --seed 4 --out " + (dir / "s.csv").string(), &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_TRUE(std::filesystem::exists(dir / "s.truth.json"));
  out = run_gaitmon("segment " + (dir / "s.csv").string() + " --out " + (dir / "seg").string(),
                    &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_EQ(first_line(dir / "seg" / "steps.csv"),
            "foot,step,t_heel_strike_s,t_toe_off_s,stance_s,peak_force_n,status");
  EXPECT_EQ(first_line(dir / "seg" / "frames.csv"),
            "foot,step,t_s,region,force_n,sensor_area_mm2,ellipse_area_mm2,case,cx_mm,cy_mm,"
            "ra_mm,rb_mm,angle_rad,pi");
  EXPECT_NE(out.find("stance s"), std::string::npos) << out;
  std::ifstream steps(dir / "seg" / "steps.csv");
  std::string line;
  int ok = 0;
  while (std::getline(steps, line)) ok += line.ends_with(",ok") ? 1 : 0;
  EXPECT_GE(ok, 14) << "a 12 s walk at 1.1 s strides has at least 7 whole steps per foot";
}

TEST(Cli, SegmentEndsAStepAtAGapAndSaysSo) {
  // The probe's session: a simulated walk whose times jump by 100 s at 5 s.
  const auto dir = test::scratch_dir("cli-gap");
  int status = -1;
  std::string out =
      run_gaitmon("simulate --duration 10 --seed 3 --out " + (dir / "s.csv").string(), &status);
  ASSERT_EQ(status, 0) << out;
  std::ifstream in(dir / "s.csv");
  std::ofstream gap(dir / "gap.csv");
  std::string line;
  while (std::getline(in, line)) {
    const auto comma = line.find(',');
    if (!line.empty() && line[0] >= '0' && line[0] <= '9' &&
        std::stod(line.substr(0, comma)) >= 5.0) {
      line = fmt::format("{:.6f}", std::stod(line.substr(0, comma)) + 100.0) + line.substr(comma);
    }
    gap << line << "\n";
  }
  gap.close();
  out = run_gaitmon("segment " + (dir / "gap.csv").string() + " --out " + (dir / "seg").string(),
                    &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("time gaps over max_gap_s: L 1, R 1"), std::string::npos) << out;
  std::ifstream steps(dir / "seg" / "steps.csv");
  std::getline(steps, line);
  int rows = 0;
  while (std::getline(steps, line)) {
    // foot,step,t_heel_strike_s,t_toe_off_s,stance_s,...
    std::istringstream fields(line);
    std::string field;
    for (int i = 0; i < 5; ++i) std::getline(fields, field, ',');
    EXPECT_LT(std::stod(field), 2.0) << line;
    ++rows;
  }
  EXPECT_GE(rows, 14) << "10 s of walking at 1.1 s a stride: about 9 steps a foot";
}

TEST(Cli, TheBundledDemoIsReproducedByTheCommandInReplayReadme) {
  const auto dir = test::scratch_dir("cli-demo");
  const auto replay = test::source_dir() / "replay";
  // The command as the README prints it, with the output moved to the scratch folder.
  const std::string readme = test::read_text(replay / "README.md");
  const std::string prefix = "build/gaitmon simulate ";
  const auto at = readme.find(prefix);
  ASSERT_NE(at, std::string::npos) << "replay/README.md shows no simulate command";
  std::string args = readme.substr(at + prefix.size(), readme.find('\n', at) - at - prefix.size());
  const std::string out_arg = "--out replay/demo-simulated-37-38.csv";
  const auto out_at = args.find(out_arg);
  ASSERT_NE(out_at, std::string::npos) << args;
  args.replace(out_at, out_arg.size(), "--out " + (dir / "demo.csv").string());
  int status = -1;
  const std::string out = run_gaitmon("simulate " + args, &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_TRUE(test::read_text(dir / "demo.csv") ==
              test::read_text(replay / "demo-simulated-37-38.csv"));
  EXPECT_NE(test::read_text(replay / "demo-simulated-37-38.csv").find("# note: SIMULATED"),
            std::string::npos);
}

TEST(Cli, BadSessionFailsNamingTheLineAndLeavesNoOutput) {
  const auto dir = test::scratch_dir("cli-bad");
  test::write_text(dir / "bad.csv", test::session_head() + test::session_row("0.0,X"));
  int status = -1;
  const std::string out = run_gaitmon(
      "segment " + (dir / "bad.csv").string() + " --out " + (dir / "o").string(), &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("bad.csv:6"), std::string::npos) << out;
  // Nothing at all: not even the folder the run made.
  EXPECT_FALSE(std::filesystem::exists(dir / "o"));
  // Into a folder that was there, the run leaves it as it was.
  std::filesystem::create_directories(dir / "kept");
  test::write_text(dir / "kept" / "notes.txt", "mine\n");
  run_gaitmon("segment " + (dir / "bad.csv").string() + " --out " + (dir / "kept").string(),
              &status);
  EXPECT_EQ(status, 2);
  EXPECT_TRUE(std::filesystem::exists(dir / "kept" / "notes.txt"));
  EXPECT_FALSE(std::filesystem::exists(dir / "kept" / "frames.csv.partial"));
}

TEST(Cli, BadConfigFailsNamingTheFileAndKey) {
  const auto dir = test::scratch_dir("cli-config");
  for (const char* name : {"gaitmon.toml", "insoles.toml", "tissue_seed_appendix_i.toml"}) {
    std::filesystem::copy_file(test::source_dir() / "config" / name, dir / name);
  }
  test::write_text(dir / "gaitmon.toml",
                   test::read_text(dir / "gaitmon.toml") + "\n[surprise]\nvalue = 1\n");
  int status = -1;
  const std::string out =
      run_gaitmon("--config " + (dir / "gaitmon.toml").string() + " simulate --duration 1 --out " +
                      (dir / "x.csv").string(),
                  &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("gaitmon.toml"), std::string::npos) << out;
  EXPECT_NE(out.find("surprise"), std::string::npos) << out;
}

// Nobody steps on the insoles: there is nothing to fit, and an output of nothing would read as
// a perfect fit (medians of 0, an NRMSE of 0 %).
TEST(Cli, ASessionWithoutACompleteStepIsRefusedByAnalyzeAndDiscrepancy) {
  const auto dir = test::scratch_dir("cli-no-steps");
  std::string text = test::session_head();
  for (int k = 0; k < 300; ++k) {
    for (const char* foot : {",L", ",R"})
      text += test::session_row(std::to_string(0.01 * k) + foot, 93, 3);
  }
  const std::string session = test::write_text(dir / "standing.csv", text).string();
  int status = -1;
  std::string out = run_gaitmon("analyze " + session + " --out " + (dir / "a").string(), &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find(session + ": no complete step to fit in 300 and 300 frames"),
            std::string::npos)
      << out;
  EXPECT_TRUE(!std::filesystem::exists(dir / "a") || std::filesystem::is_empty(dir / "a"));

  out = run_gaitmon("discrepancy " + session + " --out " + (dir / "d").string(), &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find(session + ": 0 complete steps, need at least 5 (one per fold of --folds)"),
            std::string::npos)
      << out;
  EXPECT_FALSE(std::filesystem::exists(dir / "d"));
}

// A header alone passed segment and replay as a session in which nobody walked.
TEST(Cli, ASessionWithoutFramesIsBadInputForEveryCommandThatReadsOne) {
  const auto dir = test::scratch_dir("cli-no-frames");
  const std::string session = test::write_text(dir / "empty.csv", test::session_head()).string();
  for (const std::string command : {"segment", "analyze", "discrepancy"}) {
    int status = -1;
    const std::string out =
        run_gaitmon(command + " " + session + " --out " + (dir / command).string(), &status);
    EXPECT_EQ(status, 2) << command << "\n" << out;
    EXPECT_NE(out.find("gaitmon: bad input: " + session + ": no frames"), std::string::npos)
        << command << "\n"
        << out;
    EXPECT_FALSE(std::filesystem::exists(dir / command)) << command;
  }
  int status = -1;
  const std::string out = run_gaitmon(
      "replay " + session + " --speed max --lcm-url file://" + (dir / "log").string() + "?mode=w",
      &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("gaitmon: bad input: " + session + ": no frames"), std::string::npos) << out;
}

// An empty --out made the folder commands fail after all the work, with a bare filesystem error
// and exit 1.
TEST(Cli, AnOutFolderThatCannotBeOneIsAUsageErrorBeforeAnyWork) {
  const auto dir = test::scratch_dir("cli-out-folder");
  const std::string demo = test::demo_session().string();
  const std::string file = test::write_text(dir / "file.txt", "mine\n").string();
  for (const std::string command : {"segment", "analyze", "discrepancy"}) {
    int status = -1;
    std::string out = run_gaitmon(command + " " + demo + " --out ''", &status);
    EXPECT_EQ(status, 2) << command << "\n" << out;
    EXPECT_NE(out.find("--out: the path is empty"), std::string::npos) << command << "\n" << out;
    out = run_gaitmon(command + " " + demo + " --out " + file, &status);
    EXPECT_EQ(status, 2) << command << "\n" << out;
    EXPECT_NE(out.find("--out: " + file + " exists and is not a folder"), std::string::npos)
        << command << "\n"
        << out;
    EXPECT_EQ(test::read_text(file), "mine\n");
  }
}

// A session kept in the output folder under the name of one of the command's outputs was
// deleted, as an earlier run's output, before it was read.
TEST(Cli, TheSessionIsNeverRemovedAsAnEarlierRunsOutput) {
  const auto dir = test::scratch_dir("cli-out-input");
  const std::string demo = test::read_text(test::demo_session());
  for (const std::string command : {"segment", "analyze", "discrepancy"}) {
    const std::string name = command == "discrepancy" ? "discrepancy.json" : "steps.csv";
    const std::string session = test::write_text(dir / name, demo).string();
    int status = -1;
    const std::string out =
        run_gaitmon(command + " " + session + " --out " + dir.string(), &status);
    EXPECT_EQ(status, 2) << command << "\n" << out;
    EXPECT_NE(out.find("--out: " + session + " is the file this command reads"), std::string::npos)
        << command << "\n"
        << out;
    EXPECT_EQ(test::read_text(session), demo) << command;
  }
}

// A failed rerun into the folder of a successful run left that run's files, which looked like
// this run's: now none of the command's outputs is left, and other files are kept.
TEST(Cli, AFailedRerunLeavesNoneOfTheCommandsEarlierOutputs) {
  const auto dir = test::scratch_dir("cli-rerun");
  int status = -1;
  std::string out =
      run_gaitmon("simulate --duration 4 --seed 2 --out " + (dir / "s.csv").string(), &status);
  ASSERT_EQ(status, 0) << out;
  out = run_gaitmon("segment " + (dir / "s.csv").string() + " --out " + (dir / "o").string(),
                    &status);
  ASSERT_EQ(status, 0) << out;
  ASSERT_TRUE(std::filesystem::exists(dir / "o" / "steps.csv"));
  test::write_text(dir / "o" / "notes.txt", "mine\n");
  const std::string bad =
      test::write_text(dir / "bad.csv", test::session_head() + test::session_row("0.0,X")).string();

  const struct {
    std::string command;
    std::vector<std::string> outputs;
  } commands[] = {
      {"segment", {"steps.csv", "frames.csv"}},
      {"analyze", {"steps.csv", "regions.csv", "session.json", "report.html"}},
      {"discrepancy", {"discrepancy.json", "discrepancy.html"}},
  };
  for (const auto& c : commands) {
    for (const std::string& name : c.outputs) test::write_text(dir / "o" / name, "earlier\n");
    out = run_gaitmon(c.command + " " + bad + " --out " + (dir / "o").string(), &status);
    EXPECT_EQ(status, 2) << c.command << "\n" << out;
    for (const std::string& name : c.outputs) {
      EXPECT_FALSE(std::filesystem::exists(dir / "o" / name)) << c.command << ": " << name;
    }
    EXPECT_EQ(test::read_text(dir / "o" / "notes.txt"), "mine\n") << c.command;
  }
}

// Times 20 ms apart under a header of 100 Hz: every window of the step detector is twice as long
// as meant. The frames are valid, so it is a warning naming the file and both rates.
TEST(Cli, AHeaderRateTheTimesDisagreeWithIsWarnedOf) {
  const auto dir = test::scratch_dir("cli-rate");
  std::string text = test::session_head();
  for (int k = 0; k < 100; ++k) {
    for (const char* foot : {",L", ",R"})
      text += test::session_row(std::to_string(0.02 * k) + foot);
  }
  const std::string session = test::write_text(dir / "slow.csv", text).string();
  int status = -1;
  const std::string out =
      run_gaitmon("segment " + session + " --out " + (dir / "o").string(), &status);
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find(session + ": the header says sample_rate_hz 100, but the times show 50 Hz"),
            std::string::npos)
      << out;
}

// A wrong command line is exit code 2, as a bad file is, and its message names what is wrong;
// asking for help is success.
TEST(Cli, AWrongCommandLineIsExitCodeTwoAndSaysWhy) {
  const auto dir = test::scratch_dir("cli-usage");
  int status = -1;
  std::string out = run_gaitmon(
      "analyze " + (dir / "absent.csv").string() + " --out " + (dir / "o").string(), &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("absent.csv"), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(dir / "o"));

  const std::string demo = test::demo_session().string();
  out =
      run_gaitmon("discrepancy " + demo + " --out " + (dir / "d").string() + " --folds 1", &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("--folds"), std::string::npos) << out;

  out = run_gaitmon("analyze " + demo + " --out " + (dir / "a").string() +
                        " --effects hysteresis,stress_relaxation,hysteresis",
                    &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("--effects: 'hysteresis' is given twice"), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(dir / "a"));
  out = run_gaitmon(
      "analyze " + demo + " --out " + (dir / "a").string() + " --effects none,hysteresis", &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("--effects: none cannot be combined with an effect"), std::string::npos)
      << out;
  EXPECT_FALSE(std::filesystem::exists(dir / "a"));
  // An empty name was "--effects:  not in {...}", the name itself invisible.
  out =
      run_gaitmon("analyze " + demo + " --out " + (dir / "a").string() + " --effects ''", &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("--effects: an empty effect name (none for no effect)"), std::string::npos)
      << out;
  EXPECT_FALSE(std::filesystem::exists(dir / "a"));
  // A folder as the session was "not a regular file; ... which a pipe cannot give".
  out = run_gaitmon("analyze " + dir.string() + " --out " + (dir / "a").string(), &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("session: " + dir.string() + " is a folder, not a session"), std::string::npos)
      << out;

  out = run_gaitmon("segment", &status);
  EXPECT_EQ(status, 2) << out;
  out = run_gaitmon("frobnicate", &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_NE(out.find("frobnicate"), std::string::npos) << out;

  out = run_gaitmon("analyze --help", &status);
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find("--report"), std::string::npos) << out;
}

// nan passes a plain range check (it compares false with both bounds), and CLI11 wraps "-1" and
// clamps a number too large into an unsigned option: each is a usage error naming the option.
TEST(Cli, ANumberOutsideItsRangeNanOrANegativeSeedIsAUsageError) {
  const auto dir = test::scratch_dir("cli-numbers");
  const std::string demo = test::demo_session().string();
  const std::string simulate = "simulate --duration 2 --out " + (dir / "s.csv").string() + " ";
  const std::string discrepancy = "discrepancy " + demo + " --out " + (dir / "d").string() + " ";
  const struct {
    std::string args;
    const char* says;
  } cases[] = {
      {discrepancy + "--min-shrink nan", "--min-shrink: 'nan' is not in [0, 100]"},
      {discrepancy + "--min-zero-shrink -nan", "--min-zero-shrink: '-nan' is not in [0, 100]"},
      {discrepancy + "--min-delta-bic inf", "--min-delta-bic: 'inf' is not in [0, 1000000]"},
      {discrepancy + "--min-shrink 5x", "--min-shrink: '5x' is not a number"},
      {simulate + "--duration nan", "--duration: 'nan' is not in [0.1, 86400]"},
      {simulate + "--body-mass nan", "--body-mass: 'nan' is not in [1, 300]"},
      {simulate + "--stride 0.5", "--stride: '0.5' is not in (0.5, 3]"},
      {simulate + "--noise nan", "--noise: 'nan' is not in [0, 50]"},
      {simulate + "--seed -1", "--seed: '-1' is not a whole number"},
      {simulate + "--seed 99999999999999999999",
       "--seed: '99999999999999999999' is larger than 18446744073709551615"},
  };
  for (const auto& c : cases) {
    int status = -1;
    const std::string out = run_gaitmon(c.args, &status);
    EXPECT_EQ(status, 2) << c.args << "\n" << out;
    EXPECT_NE(out.find(c.says), std::string::npos) << c.args << "\n" << out;
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "s.csv"));
  EXPECT_FALSE(std::filesystem::exists(dir / "d"));
  // Read twice (the header, then the frames), a pipe would lose what the first read took.
  std::string piped;
  EXPECT_EQ(test::run_command("cat " + demo + " | " + test::gaitmon_binary().string() +
                                  " segment /dev/stdin --out " + (dir / "g").string(),
                              &piped),
            2)
      << piped;
  EXPECT_NE(piped.find("session: /dev/stdin is not a regular file; this command reads a session "
                       "twice"),
            std::string::npos)
      << piped;
  int status = -1;
  const std::string out = run_gaitmon(simulate + "--stride 3 --seed 18446744073709551615", &status);
  EXPECT_EQ(status, 0) << out;
  EXPECT_NE(out.find("seed 18446744073709551615"), std::string::npos) << out;
}

// stdout carries results only: the log goes to stderr, so a pipe gets the table alone.
TEST(Cli, LogLinesGoToStandardErrorAndResultsToStandardOutput) {
  const auto dir = test::scratch_dir("cli-streams");
  // In a subshell: run_command sends the outer stderr to the pipe too.
  const std::string analyze = "(" + test::gaitmon_binary().string() +
                              " --log-level debug analyze " + test::demo_session().string() +
                              " --out ";
  std::string out;
  ASSERT_EQ(test::run_command(analyze + (dir / "a").string() + " 2>/dev/null)", &out), 0) << out;
  EXPECT_EQ(out.find("[debug]"), std::string::npos) << out;
  EXPECT_NE(out.find("kbar"), std::string::npos) << out;
  ASSERT_EQ(test::run_command(analyze + (dir / "b").string() + " 2>&1 >/dev/null)", &out), 0)
      << out;
  EXPECT_NE(out.find("[debug] analysed"), std::string::npos) << out;
  EXPECT_EQ(out.find("kbar"), std::string::npos) << out;
}

// analyze logs its timings at debug level: they show exactly when the level allows them.
TEST(Cli, LogLevelComesFromTheConfigUnlessGivenOnTheCommandLine) {
  const auto dir = test::scratch_dir("cli-log-level");
  for (const char* name : {"gaitmon.toml", "insoles.toml", "tissue_seed_appendix_i.toml"}) {
    std::filesystem::copy_file(test::source_dir() / "config" / name, dir / name);
  }
  std::string config = test::read_text(dir / "gaitmon.toml");
  const std::string shipped = "[log]\n# How much";
  ASSERT_NE(config.find(shipped), std::string::npos);
  const auto level = config.find("level = \"info\"", config.find(shipped));
  ASSERT_NE(level, std::string::npos);
  config.replace(level, std::string("level = \"info\"").size(), "level = \"debug\"");
  test::write_text(dir / "debug.toml", config);

  int status = -1;
  std::string out = run_gaitmon(
      "simulate --size 37-38 --duration 8 --seed 3 --out " + (dir / "s.csv").string(), &status);
  ASSERT_EQ(status, 0) << out;
  const std::string analyze = " analyze " + (dir / "s.csv").string() + " --out ";
  const std::string debug_config = "--config " + (dir / "debug.toml").string();

  out = run_gaitmon(debug_config + analyze + (dir / "a").string(), &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("[debug] analysed"), std::string::npos) << out;

  out = run_gaitmon(debug_config + " --log-level info" + analyze + (dir / "b").string(), &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_EQ(out.find("[debug]"), std::string::npos) << out;

  out = run_gaitmon("--config " + (dir / "gaitmon.toml").string() + analyze + (dir / "c").string(),
                    &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_EQ(out.find("[debug]"), std::string::npos) << out;

  out = run_gaitmon("--config " + (dir / "gaitmon.toml").string() + " --log-level debug" + analyze +
                        (dir / "d").string(),
                    &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("[debug] analysed"), std::string::npos) << out;

  // After the command's name, as users write them, the two options work the same.
  out = run_gaitmon(analyze.substr(1) + (dir / "e").string() + " " + debug_config, &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("[debug] analysed"), std::string::npos) << out;
  out = run_gaitmon(
      analyze.substr(1) + (dir / "f").string() + " " + debug_config + " --log-level info", &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_EQ(out.find("[debug]"), std::string::npos) << out;
}

}  // namespace
}  // namespace gaitmon
