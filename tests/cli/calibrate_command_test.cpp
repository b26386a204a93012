// `gaitmon calibrate` as a lab runs it: the tables on stdout, calibration.json with what was
// measured beside the config's, and calibration.toml that a config takes in place of its own
// [asymmetry] and [pooling] tables; a malformed design is a usage error that writes nothing.
#include <fcntl.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "gaitmon/config.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;

std::string read_all(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

std::string calibrate(const std::string& args, int* status) {
  std::string output;
  *status = test::run_command(test::gaitmon_binary().string() + " calibrate " + args, &output);
  return output;
}

// The measured value of one table's region, or the config's where the sessions had none.
double expected_value(const nlohmann::json& mode, const char* section, const char* key,
                      const char* region) {
  const auto& entry = mode.at(section).at(region).at(key);
  return entry.at("measured").is_null() ? entry.at("config").get<double>()
                                        : entry.at("measured").get<double>();
}

TEST(CalibrateCommand, WritesTablesThatAConfigTakesInPlaceOfItsOwn) {
  const auto dir = test::scratch_dir("calibrate-tables");
  int status = -1;
  const std::string out = calibrate(
      "--sizes 41-42,45-46 --seeds 1-2 --duration 10 --out " + (dir / "out").string(), &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("calibrate: 4 simulated sessions of 10 s (sizes 41-42, 45-46; seeds 1-2; "
                     "body mass 50-90 kg"),
            std::string::npos)
      << out;
  for (const char* table : {"\n[pooling] (each step at its own m): the SD of the pooled",
                            "\n[pooling] (each step at its own m): the SD of each step's own",
                            "\n[pooling.m_per_session] (one m per region over the session)",
                            "\n[asymmetry] (each step at its own m)",
                            "\n[asymmetry.m_per_session] (one m per region over the session)"}) {
    EXPECT_NE(out.find(table), std::string::npos) << table << "\n" << out;
  }
  const auto json = nlohmann::json::parse(read_all(dir / "out" / "calibration.json"));
  EXPECT_EQ(json.at("design").at("sessions").get<int>(), 4);
  EXPECT_EQ(json.at("design").at("sizes"), nlohmann::json({"41-42", "45-46"}));
  const auto& heel = json.at("per_step").at("pooling").at("heel").at("kbar_chain_sd_pct");
  EXPECT_EQ(heel.at("samples").get<int>(), 4);
  ASSERT_FALSE(heel.at("measured").is_null());
  // The SD measured brings the RMS of z to at most 1, and without it the steps' scatter alone
  // gives more (the heel's pooled kbar errs by more than its steps scatter: README).
  EXPECT_LE(heel.at("rms_z_measured").get<double>(), 1.0);
  EXPECT_GT(heel.at("rms_z_without").get<double>(), 1.0);
  // Each step's own: a sample per step, and with the chain's SD and its own at most 1.
  const auto& met = json.at("per_step").at("pooling").at("met3_5").at("kbar_step_sd_pct");
  EXPECT_GT(met.at("samples").get<int>(), 20);
  ASSERT_FALSE(met.at("measured").is_null());
  EXPECT_LE(met.at("rms_z_measured").get<double>(), 1.0);

  // The pools weighed each step with the config's step SDs: the command says how many of them
  // these sessions measure otherwise (four sessions cannot reproduce the shipped tables' designs).
  int otherwise = 0;
  for (const char* mode : {"per_step", "m_per_session"}) {
    for (const auto& [region, keys] : json.at(mode).at("pooling").items()) {
      for (const auto& [key, entry] : keys.items()) {
        if (key.find("_step_sd") == std::string::npos || entry.at("measured").is_null()) continue;
        if (entry.at("measured").get<double>() != entry.at("config").get<double>()) ++otherwise;
      }
    }
  }
  EXPECT_GT(otherwise, 0);
  EXPECT_EQ(json.at("step_sds_measured_otherwise").get<int>(), otherwise);
  const std::string note = fmt::format(
      "the pools weighed each step with the config's step SDs (*_step_sd), and {} of them "
      "measure otherwise here. The chain's SDs here hold for the config's;",
      otherwise);
  EXPECT_NE(out.find("\ncalibrate: " + note), std::string::npos) << out;
  EXPECT_NE(read_all(dir / "out" / "calibration.toml").find("# Note: " + note), std::string::npos);

  // calibration.toml in place of the config's [asymmetry] and [pooling] tables.
  const auto config_dir = dir / "config";
  fs::create_directories(config_dir);
  for (const char* name : {"gaitmon.toml", "insoles.toml", "tissue_seed_appendix_i.toml"}) {
    fs::copy_file(test::source_dir() / "config" / name, config_dir / name);
  }
  std::string config_text = read_all(config_dir / "gaitmon.toml");
  const auto from = config_text.find("[asymmetry]\n");
  const auto to = config_text.find("[wire]\n");
  ASSERT_NE(from, std::string::npos);
  ASSERT_NE(to, std::string::npos);
  config_text.replace(from, to - from, read_all(dir / "out" / "calibration.toml") + "\n");
  test::write_text(config_dir / "gaitmon.toml", config_text);
  const Config config = load_config(config_dir / "gaitmon.toml");
  using PerRegion = std::array<double, kRegionCount>;
  for (const bool shared_m : {false, true}) {
    const auto& mode = json.at(shared_m ? "m_per_session" : "per_step");
    const ChainSds& chain = shared_m ? config.pooling.m_per_session : config.pooling.per_step;
    const PairSds& pair = shared_m ? config.asymmetry.m_per_session : config.asymmetry.per_step;
    const std::pair<const char*, const PerRegion*> tables[] = {
        {"kbar_chain_sd_pct", &chain.kbar_chain_sd_pct},
        {"n_chain_sd", &chain.n_chain_sd},
        {"cbar_chain_sd_pct", &chain.cbar_chain_sd_pct},
        {"m_chain_sd", &chain.m_chain_sd},
        {"kbar_step_sd_pct", &chain.kbar_step_sd_pct},
        {"n_step_sd", &chain.n_step_sd},
        {"cbar_step_sd_pct", &chain.cbar_step_sd_pct},
        {"m_step_sd", &chain.m_step_sd},
        {"kbar_pair_sd_pct", &pair.kbar_pair_sd_pct},
        {"cbar_pair_sd_pct", &pair.cbar_pair_sd_pct}};
    for (const auto& [key, values] : tables) {
      const char* section =
          std::string(key).find("pair") == std::string::npos ? "pooling" : "asymmetry";
      for (Region region : kRegions) {
        const std::string name(region_name(region));
        EXPECT_DOUBLE_EQ((*values)[index_of(region)],
                         expected_value(mode, section, key, name.c_str()))
            << (shared_m ? "m_per_session " : "per_step ") << key << " " << name;
      }
    }
  }
}

TEST(CalibrateCommand, AMalformedDesignIsAUsageErrorThatSaysWhyAndWritesNothing) {
  const auto dir = test::scratch_dir("calibrate-bad");
  const struct {
    const char* args;
    const char* says;
  } cases[] = {
      {"--seeds 5-1", "seeds: the first (5) is after the last (1)"},
      {"--seeds one", "--seeds: 'one': expected a number or FIRST-LAST"},
      {"--seeds -3", "--seeds: '-3': expected a number or FIRST-LAST"},
      {"--body-mass 90-50", "body mass must be 0 < min <= max <= 300 kg, got 90 to 50"},
      {"--body-mass 60-nan", "--body-mass: '60-nan': expected a number or FIRST-LAST"},
      {"--sizes 41-42,40-41", "--sizes: 40-41 not in"},
      {"--duration 2", "--duration"},
  };
  for (const auto& c : cases) {
    int status = -1;
    const std::string out =
        calibrate(std::string(c.args) + " --out " + (dir / "out").string(), &status);
    EXPECT_EQ(status, 2) << c.args << "\n" << out;
    EXPECT_NE(out.find(c.says), std::string::npos) << c.args << "\n" << out;
    EXPECT_FALSE(fs::exists(dir / "out")) << c.args;
  }
}

// Whether `dir` holds, at any depth, a file whose name starts with `prefix`.
bool holds_file(const fs::path& dir, const std::string& prefix) {
  std::error_code error;
  for (fs::recursive_directory_iterator it(dir, error), end; !error && it != end;
       it.increment(error)) {
    if (it->path().filename().string().starts_with(prefix)) return true;
  }
  return false;
}

// Ctrl-C or SIGTERM while the sessions run: they stop at the next one the command's thread
// finishes, its scratch folder (under TMPDIR) goes, nothing is written, it says so, and it ends by
// that signal as the default action would, which would have left the sessions behind.
TEST(CalibrateCommand, AStopSignalRemovesTheScratchSessionsAndWritesNothing) {
  for (const int signal : {SIGINT, SIGTERM}) {
    SCOPED_TRACE(signal == SIGINT ? "SIGINT" : "SIGTERM");
    const auto dir = test::scratch_dir(signal == SIGINT ? "calibrate-sigint" : "calibrate-sigterm");
    const fs::path tmp = dir / "tmp";
    fs::create_directories(tmp);
    const fs::path log = dir / "log.txt";
    std::vector<std::string> args{test::gaitmon_binary().string(),
                                  "calibrate",
                                  "--seeds",
                                  "1-500",
                                  "--duration",
                                  "30",
                                  "--out",
                                  (dir / "out").string()};
    std::vector<std::string> env{"TMPDIR=" + tmp.string()};
    for (char** e = environ; *e != nullptr; ++e) {
      if (!std::string(*e).starts_with("TMPDIR=")) env.emplace_back(*e);
    }
    const auto pointers = [](std::vector<std::string>& strings) {
      std::vector<char*> out;
      for (std::string& s : strings) out.push_back(s.data());
      out.push_back(nullptr);
      return out;
    };
    std::vector<char*> argv = pointers(args);
    std::vector<char*> envp = pointers(env);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
    pid_t pid = -1;
    const int rc = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), envp.data());
    posix_spawn_file_actions_destroy(&actions);
    ASSERT_EQ(rc, 0);

    // Bounds a hang: the sessions appear within a second or two, sanitizers included.
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    while (!holds_file(tmp, "session-") && std::chrono::steady_clock::now() < until) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    const bool started = holds_file(tmp, "session-");
    ASSERT_EQ(::kill(pid, signal), 0);
    int wstatus = 0;
    pid_t ended = 0;
    while ((ended = ::waitpid(pid, &wstatus, WNOHANG)) == 0 &&
           std::chrono::steady_clock::now() < until) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    if (ended == 0) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &wstatus, 0);
    }
    EXPECT_TRUE(started) << read_all(log);
    EXPECT_EQ(ended, pid) << "still running 120 s on";
    EXPECT_TRUE(WIFSIGNALED(wstatus) && WTERMSIG(wstatus) == signal) << read_all(log);
    EXPECT_TRUE(fs::is_empty(tmp)) << read_all(log);
    EXPECT_FALSE(fs::exists(dir / "out" / "calibration.json"));
    EXPECT_NE(read_all(log).find(fmt::format("calibrate: stopped by {}; nothing written",
                                             signal == SIGINT ? "SIGINT" : "SIGTERM")),
              std::string::npos)
        << read_all(log);
  }
}

TEST(CalibrateCommand, HelpNamesTheDesignsOptionsAndTheirDefaults) {
  int status = -1;
  const std::string out = calibrate("--help", &status);
  ASSERT_EQ(status, 0) << out;
  for (const char* option : {"--sizes", "--seeds TEXT=1-20", "--duration", "--body-mass TEXT=50-90",
                             "--noise", "--max-bias", "--placement-sd", "--out"}) {
    EXPECT_NE(out.find(option), std::string::npos) << option << "\n" << out;
  }
}

}  // namespace
}  // namespace gaitmon
