// The live monitor end to end over the real bus: `gaitmon fake-insole --pty` feeds
// `gaitmon run --serial <pty>` (the real serial driver and decoder), which publishes over LCM
// udpm; lcm-logger records and a Lua client built from the lcm-gen types decodes. The steps and
// fitted parameters equal `gaitmon analyze` on the same session.
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <gaitmon/fit_t.hpp>
#include <gaitmon/step_t.hpp>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "lcm/bus_support.hpp"
#include "live_support.hpp"
#include "monitor_support.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using test::ChildProcess;
using test::expect_fits_match_regions;
using test::read_csv;
using test::roomy_config;
using Clock = std::chrono::steady_clock;

TEST(LiveRun, FakeInsoleThroughSerialAndUdpmEqualsAnalyze) {
  const test::Bus& bus = test::private_bus();
  std::cout << "LCM bus: " << bus.description << std::endl;
  const fs::path dir = test::scratch_dir("live-run");
  const fs::path session = test::cut_session(test::demo_session(), dir / "demo30.csv", 30.0);
  const std::size_t total_frames = test::session_frames(session).size();
  const fs::path config = roomy_config(dir);
  const fs::path log = dir / "bus.lcmlog";
  const std::string binary = test::gaitmon_binary().string();

  ChildProcess logger({"lcm-logger", "--lcm-url=" + bus.url, "-c", "GAITMON_(STEP|FIT|STATUS)",
                       "-q", "-f", log.string()});
  const std::unique_ptr<ChildProcess> lua = test::fit_and_status_client(bus);
  ASSERT_TRUE(lua);
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
    const auto line = lua->read_line(ChildProcess::Stdout, Clock::now() + std::chrono::seconds(1));
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
       lua->read_rest(ChildProcess::Stdout, Clock::now() + std::chrono::seconds(2))) {
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
  expect_fits_match_regions(fits, dir / "analyze" / "regions.csv", 21);

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
