// `gaitmon replay` end to end through the in-process fake driver, the wire format, the real
// decoder, the monitor and LCM (the file:// provider writes an LCM log): the fits equal
// `gaitmon analyze` on the same session (with [model] effects, the extended model's too), the
// regions' tissue at the end equals its pooled means, and SIGINT stops it cleanly.
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <gaitmon/effects_t.hpp>
#include <gaitmon/fit_t.hpp>
#include <gaitmon/status_t.hpp>
#include <gaitmon/tissue_t.hpp>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "gaitmon/lcm_publisher.hpp"
#include "lcm/bus_support.hpp"
#include "live_support.hpp"
#include "monitor_support.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

fs::path demo_30s(const fs::path& dir) {
  return test::cut_session(test::demo_session(), dir / "demo30.csv", 30.0);
}

template <typename Message>
std::vector<Message> decode(const std::vector<test::LogEvent>& events, const std::string& channel) {
  std::vector<Message> out;
  for (const test::LogEvent& e : events) {
    if (e.channel != channel) continue;
    Message m;
    if (m.decode(e.data.data(), 0, static_cast<int>(e.data.size())) < 0) {
      ADD_FAILURE() << "undecodable message on " << channel;
      continue;
    }
    out.push_back(m);
  }
  return out;
}

// `gaitmon replay SESSION --speed max`, its LCM messages logged into `dir`; the exit status.
int replay_at_max_speed(const fs::path& session, const fs::path& dir, std::string* out) {
  return test::run_command(test::gaitmon_binary().string() + " replay " + session.string() +
                               " --speed max --lcm-url file://" + (dir / "log").string() +
                               "?mode=w",
                           out);
}

using test::expect_printed;
using test::read_regions_csv;

TEST(ReplayCommand, FitsEqualAnalyzeOnTheSameSession) {
  const fs::path dir = test::scratch_dir("replay-vs-analyze");
  const fs::path session = demo_30s(dir);
  const fs::path log = dir / "replay.lcmlog";
  std::string replay_output, output;
  ASSERT_EQ(test::run_command(test::gaitmon_binary().string() + " --log-level warn replay " +
                                  session.string() + " --speed max --lcm-url 'file://" +
                                  log.string() + "?mode=w'",
                              &replay_output),
            0)
      << replay_output;
  ASSERT_EQ(test::run_command(test::gaitmon_binary().string() + " analyze " + session.string() +
                                  " --out " + (dir / "analyze").string(),
                              &output),
            0)
      << output;
  const auto expected = read_regions_csv(dir / "analyze" / "regions.csv");
  const auto events = test::read_lcm_log(log);
  const auto fits = decode<gaitmon::fit_t>(events, "GAITMON_FIT");
  ASSERT_GT(fits.size(), 20u);
  EXPECT_EQ(fits.size() * kRegionCount, expected.size()) << "one fit per analysed step";
  for (const gaitmon::fit_t& fit : fits) {
    for (const gaitmon::region_fit_t& r : fit.regions) {
      const std::string foot = fit.foot == 0 ? "L" : "R";
      const std::string where = foot + " step " + std::to_string(fit.step) + " " + r.region_name;
      const auto it = expected.find({foot, fit.step, r.region_name});
      ASSERT_NE(it, expected.end()) << where;
      const auto& row = it->second;
      const std::string status = r.status.substr(0, r.status.find(':'));
      EXPECT_EQ(row.at("status").substr(0, row.at("status").find(':')), status) << where;
      if (r.status != "ok") continue;
      expect_printed(r.kbar_n_per_mm3, row.at("kbar_n_per_mm3"), where + " kbar");
      expect_printed(r.n, row.at("n"), where + " n");
      expect_printed(r.cbar_ns_per_mm3, row.at("cbar_ns_per_mm3"), where + " cbar");
      expect_printed(r.m, row.at("m"), where + " m");
      expect_printed(r.A_mm, row.at("A_mm"), where + " A");
      expect_printed(r.B_mm, row.at("B_mm"), where + " B");
      expect_printed(r.nrmse_pct, row.at("nrmse_pct"), where + " nrmse");
    }
  }
  // The regions' tissue at the end: analyze's pooled means of the same steps (session.json), on
  // the bus and in the table printed last.
  const auto tissues = decode<gaitmon::tissue_t>(events, "GAITMON_TISSUE");
  ASSERT_GE(tissues.size(), 2u);
  const gaitmon::tissue_t& final_tissue = tissues.back();
  EXPECT_TRUE(final_tissue.final_estimate);
  std::ifstream session_json(dir / "analyze" / "session.json");
  const nlohmann::json session_regions = nlohmann::json::parse(session_json)["regions"];
  int pooled = 0;
  for (const gaitmon::region_tissue_t& r : final_tissue.regions) {
    const nlohmann::json& pooling = session_regions.at(r.region_name).at("pooling");
    EXPECT_EQ(r.steps, pooling.at("steps").get<int>()) << r.region_name;
    EXPECT_EQ(r.status == "ok", pooling.at("pooled").get<bool>()) << r.region_name;
    if (r.status != "ok") {
      EXPECT_EQ(r.status, "not_pooled:" + pooling.at("note").get<std::string>());
      EXPECT_NE(output.find(r.region_name), std::string::npos);
      continue;
    }
    ++pooled;
    const nlohmann::json& mean = pooling.at("mean");
    const nlohmann::json& se = pooling.at("se");
    // The same pool of the same fits, its sums taken in the workers' order.
    const auto near = [&](double got, const nlohmann::json& expected, const std::string& what) {
      EXPECT_NEAR(got, expected.get<double>(), 1e-8 * std::abs(expected.get<double>()))
          << r.region_name << " " << what;
    };
    near(r.kbar_n_per_mm3, mean.at("kbar_n_per_mm3"), "kbar");
    near(r.n, mean.at("n"), "n");
    near(r.cbar_ns_per_mm3, mean.at("cbar_ns_per_mm3"), "cbar");
    near(r.m, mean.at("m"), "m");
    near(r.se_kbar, se.at("kbar_n_per_mm3"), "se_kbar");
    near(r.se_n, se.at("n"), "se_n");
    near(r.se_cbar, se.at("cbar_ns_per_mm3"), "se_cbar");
    near(r.se_m, se.at("m"), "se_m");
  }
  EXPECT_GE(pooled, 5);
  const auto table = replay_output.find("tissue over the steps of");
  ASSERT_NE(table, std::string::npos) << replay_output;
  EXPECT_NE(replay_output.find("\n  heel ", table), std::string::npos) << replay_output;
  EXPECT_NE(replay_output.find("not pooled: the pooled mean leaves the fit bounds", table),
            std::string::npos)
      << replay_output;

  const auto statuses = decode<gaitmon::status_t>(events, "GAITMON_STATUS");
  ASSERT_FALSE(statuses.empty());
  EXPECT_EQ(statuses.back().connection, "finished");
  EXPECT_EQ(statuses.back().ring_drops, 0);
  EXPECT_EQ(statuses.back().step_drops, 0);
  EXPECT_EQ(statuses.back().fits_published, static_cast<std::int64_t>(fits.size()));
  EXPECT_EQ(statuses.back().frames_decoded,
            static_cast<std::int64_t>(test::session_frames(session).size()));
}

// [model] effects in the config makes the replay's monitor fit the extended model: its final
// GAITMON_EFFECTS message equals `gaitmon analyze`'s extended_model (which reads the same
// setting) on the same session, which is shorter than the monitor's window of 100 steps.
TEST(ReplayCommand, ConfiguredEffectsEqualAnalyzeOnTheSameSession) {
  const fs::path dir = test::scratch_dir("replay-effects");
  const fs::path session = demo_30s(dir);
  for (const char* name : {"gaitmon.toml", "insoles.toml", "tissue_seed_appendix_i.toml"}) {
    fs::copy_file(test::source_dir() / "config" / name, dir / name);
  }
  std::ifstream in(dir / "gaitmon.toml");
  std::string config((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto at = config.find("\neffects = []\n");
  ASSERT_NE(at, std::string::npos);
  config.replace(at, std::string("\neffects = []\n").size(),
                 "\neffects = [\"impact_transient\"]\n");
  test::write_text(dir / "gaitmon.toml", config);
  const std::string gaitmon =
      test::gaitmon_binary().string() + " --config " + (dir / "gaitmon.toml").string();

  const fs::path log = dir / "replay.lcmlog";
  std::string output;
  ASSERT_EQ(test::run_command(gaitmon + " --log-level warn replay " + session.string() +
                                  " --speed max --lcm-url 'file://" + log.string() + "?mode=w'",
                              &output),
            0)
      << output;
  EXPECT_NE(output.find("effects, final, over "), std::string::npos) << output;
  // The end of the session is the replay's plan, not a warning.
  EXPECT_EQ(output.find("link disconnected"), std::string::npos) << output;
  ASSERT_EQ(test::run_command(
                gaitmon + " analyze " + session.string() + " --out " + (dir / "analyze").string(),
                &output),
            0)
      << output;

  std::ifstream json_in(dir / "analyze" / "session.json");
  const nlohmann::json extended = nlohmann::json::parse(json_in).at("extended_model");
  ASSERT_EQ(extended.at("effects").size(), 1u);
  const nlohmann::json& expected = extended.at("effects").at(0);
  EXPECT_EQ(expected.at("name"), "impact_transient");
  // --effects none turns the config's effects off.
  ASSERT_EQ(test::run_command(gaitmon + " analyze " + session.string() + " --effects none --out " +
                                  (dir / "baseline").string(),
                              &output),
            0)
      << output;
  std::ifstream baseline_in(dir / "baseline" / "session.json");
  EXPECT_TRUE(nlohmann::json::parse(baseline_in).at("extended_model").is_null());

  const auto events = test::read_lcm_log(log);
  const auto reports = decode<gaitmon::effects_t>(events, "GAITMON_EFFECTS");
  ASSERT_FALSE(reports.empty());
  const gaitmon::effects_t& final_report = reports.back();
  EXPECT_TRUE(final_report.final_estimate);
  EXPECT_EQ(final_report.steps,
            static_cast<std::int32_t>(decode<gaitmon::fit_t>(events, "GAITMON_FIT").size()));
  const auto near = [](double value, double expected_value) {
    return std::abs(value - expected_value) <= 1e-9 * std::max(1.0, std::abs(expected_value));
  };
  EXPECT_TRUE(near(final_report.baseline_nrmse_pct, extended.at("baseline_nrmse_pct")));
  EXPECT_TRUE(near(final_report.extended_nrmse_pct, extended.at("extended_nrmse_pct")));
  EXPECT_TRUE(
      near(final_report.extended_heldout_nrmse_pct, extended.at("extended_heldout_nrmse_pct")));
  ASSERT_EQ(static_cast<std::size_t>(final_report.num_params), expected.at("params").size());
  for (const gaitmon::effect_param_t& p : final_report.params) {
    EXPECT_EQ(p.effect, "impact_transient");
    ASSERT_TRUE(expected.at("params").contains(p.name)) << p.name;
    const nlohmann::json& e = expected.at("params").at(p.name);
    EXPECT_TRUE(near(p.value, e.at("value"))) << p.name << " " << p.value << " vs " << e;
    if (e.at("se").is_number()) {
      EXPECT_TRUE(near(p.se, e.at("se"))) << p.name << " SE " << p.se << " vs " << e;
    } else {
      EXPECT_TRUE(std::isnan(p.se)) << p.name << " SE " << p.se << " vs " << e;
    }
  }
}

// A bus that refuses every message (an LCM log opened for reading): the replay runs to its
// end, logs the loss and counts it in its closing line.
TEST(ReplayCommand, MessagesTheBusRefusesAreLoggedAndCounted) {
  const fs::path dir = test::scratch_dir("replay-refused");
  const fs::path session = test::cut_session(test::demo_session(), dir / "demo5.csv", 5.0);
  const fs::path log = dir / "one.lcmlog";
  {
    LcmSettings settings;
    settings.url = "file://" + log.string() + "?mode=w";
    LcmPublisher(settings).publish(StatusReport{});  // LCM reads only a log that holds an event
  }
  std::string output;
  ASSERT_EQ(test::run_command(test::gaitmon_binary().string() + " --log-level warn replay " +
                                  session.string() + " --speed max --lcm-url 'file://" +
                                  log.string() + "?mode=r'",
                              &output),
            0)
      << output;
  EXPECT_NE(output.find("LCM: a message on GAITMON_"), std::string::npos) << output;
  const std::size_t frames = test::session_frames(session).size();
  const auto at = output.find(" messages lost (publishing failed)");
  ASSERT_NE(at, std::string::npos) << output;
  const std::size_t lost = std::stoul(output.substr(output.rfind(' ', at - 1) + 1));
  EXPECT_GE(lost, frames) << "every frame report at least: " << output;
}

// A URL LCM cannot open and a speed too slow for the pacer are command-line errors (exit 2).
TEST(ReplayCommand, BadOptionsAreExitCodeTwoAndSayWhy) {
  struct Case {
    std::string args;
    std::string message;
  };
  for (const Case& c : {
           Case{"--lcm-url bogus://", "--lcm-url: LCM cannot open \"bogus://\""},
           Case{"--lcm-url memq", "--lcm-url: LCM cannot open \"memq\""},
           Case{"--speed 1e-300", "--speed: must be a number >= 0.001 (x real time) or max"},
       }) {
    SCOPED_TRACE(c.args);
    std::string out;
    EXPECT_EQ(test::run_command(
                  "timeout 60 " + test::gaitmon_binary().string() + " replay " + c.args, &out),
              2)
        << out;
    EXPECT_NE(out.find(c.message), std::string::npos) << out;
  }
}

// A bad line halfway is an input error (exit 2, the file and line named), found by the check of
// the whole file before the first frame is played: nothing is published (it used to come after
// the fits of the steps before it).
TEST(ReplayCommand, ABadLineHalfwayIsAnInputErrorNamingTheLine) {
  const fs::path dir = test::scratch_dir("replay-bad-line");
  const fs::path good = test::cut_session(test::demo_session(), dir / "good.csv", 10.0);
  std::ifstream in(good);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  const std::size_t bad = lines.size() / 2;
  lines[bad] = "1.0,L,not-a-number";
  std::string text;
  for (const std::string& line : lines) text += line + "\n";
  const fs::path session = test::write_text(dir / "bad.csv", text);

  std::string out;
  EXPECT_EQ(replay_at_max_speed(session, dir, &out), 2) << out;
  EXPECT_NE(out.find("bad.csv:" + std::to_string(bad + 1)), std::string::npos) << out;
  EXPECT_TRUE(!fs::exists(dir / "log") || test::read_lcm_log(dir / "log").empty()) << out;
}

// The default config's max_gap_s (0.055 s) is under 1.5 periods at 20 Hz: the session cannot
// be segmented, which is bad input named like `analyze` names it, not an internal error.
TEST(ReplayCommand, ASessionRateTheConfigCannotSegmentIsAnInputError) {
  const fs::path dir = test::scratch_dir("replay-slow");
  const fs::path session =
      test::write_text(dir / "slow.csv", test::session_head("20") + test::session_row("0,L"));
  std::string out;
  EXPECT_EQ(replay_at_max_speed(session, dir, &out), 2) << out;
  EXPECT_NE(out.find(session.string() + ": sample_rate_hz 20 does not fit [segmentation] of "),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("max_gap_s 0.055 s is under 1.5 sample periods"), std::string::npos) << out;
}

// How long the shutdown takes is printed, not asserted: a sanitizer build on a loaded machine
// takes what it takes; 10 s without exit is a hang.
TEST(ReplayCommand, SigintStopsCleanlyAfterAFinalStatus) {
  const fs::path dir = test::scratch_dir("replay-sigint");
  const fs::path log = dir / "replay.lcmlog";
  test::ChildProcess replay({test::gaitmon_binary().string(), "replay", "--speed", "1", "--lcm-url",
                             "file://" + log.string() + "?mode=w"});
  // The first fitted step is printed about 1.5 s in.
  const auto first = replay.read_until(test::ChildProcess::Stdout, "stance",
                                       Clock::now() + std::chrono::seconds(60));
  ASSERT_FALSE(first.empty()) << "no step line from gaitmon replay";
  const auto sent = Clock::now();
  replay.signal(SIGINT);
  const auto status = replay.wait(sent + std::chrono::seconds(10));
  const double took_s = std::chrono::duration<double>(Clock::now() - sent).count();
  ASSERT_TRUE(status.has_value()) << "still running 10 s after SIGINT";
  EXPECT_EQ(*status, 0) << replay.stderr_text(Clock::now() + std::chrono::seconds(2));
  std::printf("replay exited %.2f s after SIGINT\n", took_s);
  const auto statuses = decode<gaitmon::status_t>(test::read_lcm_log(log), "GAITMON_STATUS");
  ASSERT_FALSE(statuses.empty());
  EXPECT_EQ(statuses.back().connection, "finished");
  EXPECT_GT(statuses.back().frames_decoded, 0);
}

// With no USB device present `run --usb` keeps trying to connect, and SIGINT still stops it
// cleanly; --usb and --serial together are refused.
TEST(RunCommand, UsbWithoutADeviceWaitsAndStopsOnSigint) {
  const fs::path dir = test::scratch_dir("run-usb");
  const fs::path log = dir / "run.lcmlog";
  test::ChildProcess run({test::gaitmon_binary().string(), "run", "--usb", "--lcm-url",
                          "file://" + log.string() + "?mode=w"});
  const auto started = run.read_until(test::ChildProcess::Stderr, "USB 0000:0000",
                                      Clock::now() + std::chrono::seconds(30));
  ASSERT_FALSE(started.empty()) << "gaitmon run --usb did not start";
  bool warned = false;
  for (const std::string& line : started) {
    warned = warned || line.find(
                           "are 0000:0000, the shipped placeholders: set them to your "
                           "insole's") != std::string::npos;
  }
  EXPECT_TRUE(warned) << "no word that the shipped [usb] ids match no device";
  run.signal(SIGINT);
  const auto status = run.wait(Clock::now() + std::chrono::seconds(10));
  ASSERT_TRUE(status.has_value()) << "still running 10 s after SIGINT";
  EXPECT_EQ(*status, 0) << run.stderr_text(Clock::now() + std::chrono::seconds(2));

  int refused = -1;
  std::string out;
  refused = test::run_command(
      test::gaitmon_binary().string() + " run --usb --serial /dev/null 2>&1", &out);
  EXPECT_NE(refused, 0);
  EXPECT_NE(out.find("excludes"), std::string::npos) << out;
}

}  // namespace
}  // namespace gaitmon
