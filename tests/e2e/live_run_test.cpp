// The live monitor end to end over the real bus: `gaitmon fake-insole --pty` feeds
// `gaitmon run --serial <pty>` (the real serial driver and decoder), which publishes over LCM
// udpm; lcm-logger records and a Lua client built from the lcm-gen types decodes. The steps and
// fitted parameters equal `gaitmon analyze` on the same session.
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <gaitmon/fit_t.hpp>
#include <gaitmon/step_t.hpp>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "lcm/bus_support.hpp"
#include "monitor_support.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using test::ChildProcess;
using Clock = std::chrono::steady_clock;

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> fields;
  std::stringstream in(line);
  std::string field;
  while (std::getline(in, field, ',')) fields.push_back(field);
  if (!line.empty() && line.back() == ',') fields.emplace_back();
  return fields;
}

// A CSV of `gaitmon analyze` as rows of column -> text.
std::vector<std::map<std::string, std::string>> read_csv(const fs::path& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  const auto columns = split(line);
  std::vector<std::map<std::string, std::string>> rows;
  while (std::getline(in, line)) {
    const auto fields = split(line);
    std::map<std::string, std::string> row;
    for (std::size_t i = 0; i < columns.size() && i < fields.size(); ++i)
      row[columns[i]] = fields[i];
    rows.push_back(row);
  }
  return rows;
}

// analyze prints 4-6 significant digits; LCM carries full doubles.
void expect_printed(double value, const std::string& printed, const std::string& what) {
  const double expected = std::stod(printed);
  EXPECT_NEAR(value, expected, 1e-3 * std::abs(expected) + 1e-12) << what;
}

// The shipped config with room for every step and frame: the comparison needs all of them,
// whatever the load on the machine. Per-frame reports are off: UDP has no flow control, and
// 800 frame messages a second (4 x real time) overflow a listener's socket buffer when the
// machine is busy, taking step and fit messages with them. The comparison needs only steps and
// fits; frame_t crosses the real bus in tests/lcm/lcm_bus_test.cpp.
fs::path roomy_config(const fs::path& dir) {
  for (const char* file : {"gaitmon.toml", "insoles.toml", "tissue_seed_appendix_i.toml"}) {
    fs::copy_file(test::source_dir() / "config" / file, dir / file);
  }
  std::ifstream in(dir / "gaitmon.toml");
  std::stringstream text;
  text << in.rdbuf();
  std::string toml = text.str();
  const auto set = [&](const std::string& from, const std::string& to) {
    const auto at = toml.find(from);
    if (at == std::string::npos) throw std::logic_error("not in the config: " + from);
    toml.replace(at, from.size(), to);
  };
  set("max_step_backlog = 32", "max_step_backlog = 100000");
  set("capacity_frames = 4096", "capacity_frames = 65536");
  set("publish_frames = true", "publish_frames = false");
  test::write_text(dir / "gaitmon.toml", toml);
  return dir / "gaitmon.toml";
}

TEST(LiveRun, FakeInsoleThroughSerialAndUdpmEqualsAnalyze) {
  const test::Bus& bus = test::private_bus();
  std::cout << "LCM bus: " << bus.description << std::endl;
  const fs::path dir = test::scratch_dir("live-run");
  const fs::path session = test::cut_session(
      test::source_dir() / "replay" / "demo-simulated-37-38.csv", dir / "demo30.csv", 30.0);
  const std::size_t total_frames = test::session_frames(session).size();
  const fs::path config = roomy_config(dir);
  const fs::path log = dir / "bus.lcmlog";
  const std::string binary = test::gaitmon_binary().string();

  ChildProcess logger({"lcm-logger", "--lcm-url=" + bus.url, "-c", "GAITMON_(STEP|FIT|STATUS)",
                       "-q", "-f", log.string()});
  ChildProcess lua({"lua5.2", test::source_dir().string() + "/tests/lcm/subscriber.lua", "--url",
                    bus.url, "--types", GAITMON_LCM_LUA_DIR, "--timeout-s", "300",
                    "GAITMON_FIT=fit_t", "GAITMON_STATUS=status_t"});
  ASSERT_FALSE(
      lua.read_until(ChildProcess::Stdout, "ready", Clock::now() + std::chrono::seconds(20))
          .empty())
      << "the Lua client did not start";
  ChildProcess fake({binary, "fake-insole", session.string(), "--pty", "--speed", "4", "--hold"});
  const auto pty = fake.read_line(ChildProcess::Stdout, Clock::now() + std::chrono::seconds(20));
  ASSERT_TRUE(pty.has_value()) << "fake-insole printed no pty";
  ChildProcess run({binary, "--config", config.string(), "--log-level", "warn", "run", "--serial",
                    *pty, "--lcm-url", bus.url});

  // The Lua client's status lines say when every frame has been decoded.
  std::vector<json> fits;
  bool all_decoded = false;
  const auto deadline = Clock::now() + std::chrono::seconds(240);
  while (!all_decoded && Clock::now() < deadline) {
    const auto line = lua.read_line(ChildProcess::Stdout, Clock::now() + std::chrono::seconds(1));
    if (!line || line->empty() || line->front() != '{') continue;
    json message = json::parse(*line);
    ASSERT_FALSE(message.contains("error")) << *line;
    if (message["channel"] == "GAITMON_FIT") fits.push_back(message["message"]);
    if (message["channel"] == "GAITMON_STATUS" &&
        message["message"]["frames_decoded"].get<std::size_t>() == total_frames) {
      all_decoded = true;
    }
  }
  ASSERT_TRUE(all_decoded) << "gaitmon run never reported all " << total_frames << " frames";
  run.signal(SIGINT);
  const auto run_status = run.wait(Clock::now() + std::chrono::seconds(10));
  ASSERT_TRUE(run_status.has_value()) << "gaitmon run still running 10 s after SIGINT";
  EXPECT_EQ(*run_status, 0);
  fake.signal(SIGINT);
  // The fits finished after the last status line we read, and the final status.
  json final_status;
  for (const std::string& line :
       lua.read_rest(ChildProcess::Stdout, Clock::now() + std::chrono::seconds(2))) {
    if (line.empty() || line.front() != '{') continue;
    json message = json::parse(line);
    if (message["channel"] == "GAITMON_FIT") fits.push_back(message["message"]);
    if (message["channel"] == "GAITMON_STATUS") final_status = message["message"];
  }
  ASSERT_FALSE(final_status.is_null());
  EXPECT_EQ(final_status["connection"], "finished");
  EXPECT_EQ(final_status["ring_drops"], 0);
  EXPECT_EQ(final_status["step_drops"], 0);
  EXPECT_EQ(final_status["crc_errors"], 0);
  EXPECT_EQ(final_status["fits_published"].get<std::size_t>(), fits.size());
  logger.signal(SIGINT);
  ASSERT_EQ(logger.wait(Clock::now() + std::chrono::seconds(5)), 0);

  std::string output;
  ASSERT_EQ(test::run_command(
                binary + " analyze " + session.string() + " --out " + (dir / "analyze").string(),
                &output),
            0)
      << output;

  // Fits, as the Lua client decoded them, against analyze's regions.csv.
  std::map<std::tuple<std::string, int, std::string>, std::map<std::string, std::string>> regions;
  for (auto& row : read_csv(dir / "analyze" / "regions.csv")) {
    regions[{row["foot"], std::stoi(row["step"]), row["region"]}] = row;
  }
  ASSERT_GT(fits.size(), 20u);
  EXPECT_EQ(fits.size() * kRegionCount, regions.size());
  for (const json& fit : fits) {
    const std::string foot = fit["foot"] == 0 ? "L" : "R";
    for (const json& r : fit["regions"]) {
      const std::string name = r["region_name"];
      const std::string where =
          foot + " step " + std::to_string(fit["step"].get<int>()) + " " + name;
      const auto it = regions.find({foot, fit["step"].get<int>(), name});
      ASSERT_NE(it, regions.end()) << where;
      const std::string status = r["status"];
      EXPECT_EQ(it->second.at("status").substr(0, it->second.at("status").find(':')),
                status.substr(0, status.find(':')))
          << where;
      if (status != "ok") continue;
      expect_printed(r["kbar_n_per_mm3"], it->second.at("kbar_n_per_mm3"), where + " kbar");
      expect_printed(r["n"], it->second.at("n"), where + " n");
      expect_printed(r["cbar_ns_per_mm3"], it->second.at("cbar_ns_per_mm3"), where + " cbar");
      expect_printed(r["m"], it->second.at("m"), where + " m");
      expect_printed(r["nrmse_pct"], it->second.at("nrmse_pct"), where + " nrmse");
    }
  }

  // Steps, as lcm-logger recorded them, against analyze's steps.csv.
  std::map<std::pair<std::string, int>, std::pair<double, double>> logged_steps;
  std::size_t logged_fits = 0;
  for (const test::LogEvent& e : test::read_lcm_log(log)) {
    if (e.channel == "GAITMON_FIT") ++logged_fits;
    if (e.channel != "GAITMON_STEP") continue;
    step_t s;
    ASSERT_EQ(s.decode(e.data.data(), 0, static_cast<int>(e.data.size())),
              static_cast<int>(e.data.size()));
    auto& times = logged_steps[{s.foot == 0 ? "L" : "R", s.step}];
    (s.kind == step_t::HEEL_STRIKE ? times.first : times.second) = s.t_s;
  }
  EXPECT_EQ(logged_fits, fits.size());
  const auto steps = read_csv(dir / "analyze" / "steps.csv");
  ASSERT_EQ(logged_steps.size(), steps.size());
  for (const auto& row : steps) {
    const auto it = logged_steps.find({row.at("foot"), std::stoi(row.at("step"))});
    ASSERT_NE(it, logged_steps.end()) << row.at("foot") << row.at("step");
    EXPECT_EQ(it->second.first, std::stod(row.at("t_heel_strike_s")));
    EXPECT_EQ(it->second.second, std::stod(row.at("t_toe_off_s")));
  }
}

}  // namespace
}  // namespace gaitmon
