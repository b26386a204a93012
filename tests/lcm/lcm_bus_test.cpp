// LcmPublisher over real udpm with clients in other processes: lcm-logger records, a Lua client
// built from the lcm-gen types decodes live, and `gaitmon spy` prints JSON lines; each is
// compared with what was published.
#include <gtest/gtest.h>

#include <csignal>
#include <functional>
#include <gaitmon/effects_t.hpp>
#include <gaitmon/fit_t.hpp>
#include <gaitmon/frame_t.hpp>
#include <gaitmon/raw_t.hpp>
#include <gaitmon/status_t.hpp>
#include <gaitmon/step_t.hpp>
#include <gaitmon/tissue_t.hpp>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <string>

#include "gaitmon/lcm_publisher.hpp"
#include "lcm/bus_support.hpp"
#include "lcm/sample_reports.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

using nlohmann::json;
using Clock = std::chrono::steady_clock;
using test::ChildProcess;

const std::set<std::string> kAllChannels{"GAITMON_FRAME",  "GAITMON_STEP", "GAITMON_FIT",
                                         "GAITMON_STATUS", "GAITMON_RAW",  "GAITMON_EFFECTS",
                                         "GAITMON_TISSUE"};

class LcmBus : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    std::cout << "LCM bus: " << test::private_bus().description << std::endl;
  }

  LcmSettings settings() const {
    LcmSettings s;
    s.url = test::private_bus().url;
    s.raw_enabled = true;
    return s;
  }
};

// A listener's JSON lines, split into warm-up messages and the rest.
struct Listener {
  Listener(ChildProcess* p, std::function<bool(const json&)> warmup)
      : process(p), is_warmup(std::move(warmup)) {}

  ChildProcess* process;
  std::function<bool(const json&)> is_warmup;
  bool warm = false;
  std::vector<json> messages;

  void read_until(Clock::time_point deadline) {
    while (auto line = process->read_line(ChildProcess::Stdout, deadline)) {
      if (line->empty() || line->front() != '{') continue;
      json parsed = json::parse(*line);
      if (is_warmup(parsed)) {
        warm = true;
      } else {
        messages.push_back(std::move(parsed));
      }
      if (Clock::now() >= deadline) return;
    }
  }
};

StatusReport warmup_status() {
  StatusReport s;
  s.utime = 1;
  s.connection = "warmup";
  return s;
}

// Publishes warm-up status messages until every listener has heard one and `also_ready` holds
// (UDP has no handshake: a subscriber is ready once it has received something).
void warm_up(LcmPublisher& publisher, std::vector<Listener*> listeners,
             const std::function<bool()>& also_ready) {
  const auto give_up = Clock::now() + std::chrono::seconds(20);
  while (Clock::now() < give_up) {
    publisher.publish(warmup_status());
    bool all = also_ready();
    for (Listener* l : listeners) {
      l->read_until(Clock::now() + std::chrono::milliseconds(50));
      all = all && l->warm;
    }
    if (all) return;
  }
  std::string said;
  for (Listener* l : listeners) {
    said += l->process->stderr_text(Clock::now() + std::chrono::seconds(1));
  }
  FAIL() << "the listeners heard nothing for 20 s; on stderr they said:\n" << said;
}

void read_messages(Listener& listener, std::size_t count) {
  const auto deadline = Clock::now() + std::chrono::seconds(10);
  while (listener.messages.size() < count && Clock::now() < deadline) {
    listener.read_until(std::min(deadline, Clock::now() + std::chrono::milliseconds(200)));
  }
}

// The Lua client prints the lcm-gen Lua objects: LCM field names, feet and kinds as numbers,
// 1-based arrays as JSON arrays. Expected values are the samples', written out here.
json lua_expected_step() {
  const StepEvent e = test::sample_step();
  return {{"utime", e.utime},  {"foot", 0},        {"step", e.step}, {"kind", 1},
          {"complete", false}, {"frame", e.frame}, {"t_s", e.t_s}};
}

// The fields a region's fit and its pool share, the i-th region by its name written out.
template <typename RegionReport>
json lua_expected_region(int i, const RegionReport& g) {
  const char* const names[] = {
      "heel",   "midfoot_posterior", "midfoot_anterior", "met1_2", "met3_5", "toe1", "toe2",
      "toes3_5"};
  return {{"region", i},        {"region_name", names[i]},
          {"status", g.status}, {"kbar_n_per_mm3", g.kbar_n_per_mm3},
          {"n", g.n},           {"cbar_ns_per_mm3", g.cbar_ns_per_mm3},
          {"m", g.m},           {"se_kbar", g.se_kbar},
          {"se_n", g.se_n},     {"se_cbar", g.se_cbar},
          {"se_m", g.se_m}};
}

json lua_expected_fit() {
  const FitReport r = test::sample_fit();
  json regions = json::array();
  for (int i = 0; i < 8; ++i) {
    const RegionFitReport& g = r.regions[static_cast<std::size_t>(i)];
    json region = lua_expected_region(i, g);
    region.update({{"se_kbar_total", g.se_kbar_total},
                   {"se_n_total", g.se_n_total},
                   {"se_cbar_total", g.se_cbar_total},
                   {"se_m_total", g.se_m_total},
                   {"A_mm", g.A_mm},
                   {"B_mm", g.B_mm},
                   {"C_mm", g.C_mm},
                   {"d0_mm", g.d0_mm},
                   {"nrmse_pct", g.nrmse_pct},
                   {"m_steps", g.m_steps}});
    regions.push_back(std::move(region));
  }
  return {{"utime", r.utime},
          {"foot", 1},
          {"step", r.step},
          {"t_heel_strike_s", r.t_heel_strike_s},
          {"t_toe_off_s", r.t_toe_off_s},
          {"nrmse_total_pct", r.nrmse_total_pct},
          {"latency_ms", r.latency_ms},
          {"effects_inside", r.effects_inside},
          {"effects_utime", r.effects_utime},
          {"regions", regions}};
}

json lua_expected_effects() {
  const EffectsReport r = test::sample_effects();
  json params = json::array();
  for (const EffectParamReport& p : r.params) {
    params.push_back({{"effect", p.effect}, {"name", p.name}, {"value", p.value}, {"se", p.se}});
  }
  return {{"utime", r.utime},
          {"final_estimate", true},
          {"steps", r.steps},
          {"t_first_heel_strike_s", r.t_first_heel_strike_s},
          {"t_last_toe_off_s", r.t_last_toe_off_s},
          {"baseline_nrmse_pct", r.baseline_nrmse_pct},
          {"extended_nrmse_pct", r.extended_nrmse_pct},
          {"baseline_heldout_nrmse_pct", r.baseline_heldout_nrmse_pct},
          {"extended_heldout_nrmse_pct", r.extended_heldout_nrmse_pct},
          {"num_params", 3},
          {"params", params}};
}

json lua_expected_tissue() {
  const TissueReport r = test::sample_tissue();
  json regions = json::array();
  for (int i = 0; i < 8; ++i) {
    const RegionTissueReport& g = r.regions[static_cast<std::size_t>(i)];
    json region = lua_expected_region(i, g);
    region["steps"] = g.steps;
    regions.push_back(std::move(region));
  }
  return {{"utime", r.utime},
          {"final_estimate", false},
          {"foot", 0},
          {"step", r.step},
          {"t_first_heel_strike_s", r.t_first_heel_strike_s},
          {"t_last_toe_off_s", r.t_last_toe_off_s},
          {"regions", regions}};
}

json lua_expected_status() {
  const StatusReport s = test::sample_status();
  return {{"utime", s.utime},           {"connection", "connected"}, {"bytes_received", 123456789},
          {"frames_decoded", 98765},    {"crc_errors", 3},           {"resyncs", 5},
          {"frames_truncated", 37},     {"header_errors", 41},       {"sequence_restarts", 43},
          {"segmentation_gaps", 47},    {"frames_lost_sequence", 7}, {"reconnects", 2},
          {"transfers_overflowed", 53}, {"ring_depth", 11},          {"ring_drops", 13},
          {"frames_processed", 98700},  {"frames_rejected", 31},     {"steps_detected", 17},
          {"step_backlog", 19},         {"step_drops", 23},          {"fits_published", 29},
          {"fits_failed", 31},          {"fit_latency_p50_ms", 1.5}, {"fit_latency_p99_ms", 12.25}};
}

const json* find_channel(const std::vector<json>& messages, const std::string& channel) {
  for (const json& m : messages) {
    if (m.value("channel", "") == channel) return &m;
  }
  return nullptr;
}

TEST_F(LcmBus, LoggerAndLuaClientReceiveWhatIsPublished) {
  const auto dir = test::scratch_dir("lcm-bus");
  const auto log_path = dir / "bus.log";
  // -c: LCM's udpm also sends its own LCM_SELF_TEST message.
  ChildProcess logger({"lcm-logger", "--lcm-url=" + settings().url, "-c", "GAITMON_.*", "-q", "-f",
                       log_path.string()});
  ChildProcess lua({"lua5.2", std::string(GAITMON_SOURCE_DIR) + "/tests/lcm/subscriber.lua",
                    "--url", settings().url, "--types", GAITMON_LCM_LUA_DIR, "--timeout-s", "60"});
  Listener lua_listener{&lua, [](const json& j) {
                          return j.value("channel", "") == "GAITMON_STATUS" &&
                                 j["message"].value("connection", "") == "warmup";
                        }};
  LcmPublisher publisher(settings());
  warm_up(publisher, {&lua_listener}, [&] {
    for (const auto& event : test::read_lcm_log(log_path)) {
      if (event.channel == "GAITMON_STATUS") return true;
    }
    return false;
  });
  ASSERT_TRUE(lua_listener.warm);
  test::publish_samples(publisher);
  read_messages(lua_listener, 7);
  EXPECT_EQ(publisher.failed_publishes(), 0U);

  // The Lua client decoded each message with the lcm-gen Lua types.
  std::set<std::string> lua_channels;
  for (const json& m : lua_listener.messages) {
    ASSERT_FALSE(m.contains("error")) << m.dump();
    lua_channels.insert(m["channel"].get<std::string>());
  }
  EXPECT_EQ(lua_channels, kAllChannels);
  const json* step = find_channel(lua_listener.messages, "GAITMON_STEP");
  const json* fit = find_channel(lua_listener.messages, "GAITMON_FIT");
  const json* status = find_channel(lua_listener.messages, "GAITMON_STATUS");
  ASSERT_TRUE(step && fit && status);
  EXPECT_EQ((*step)["type"], "gaitmon.step_t");
  EXPECT_EQ((*step)["message"], lua_expected_step());
  EXPECT_EQ((*fit)["type"], "gaitmon.fit_t");
  EXPECT_EQ((*fit)["message"], lua_expected_fit());
  EXPECT_EQ((*status)["type"], "gaitmon.status_t");
  EXPECT_EQ((*status)["message"], lua_expected_status());
  const json* effects = find_channel(lua_listener.messages, "GAITMON_EFFECTS");
  ASSERT_TRUE(effects);
  EXPECT_EQ((*effects)["type"], "gaitmon.effects_t");
  EXPECT_EQ((*effects)["message"], lua_expected_effects());
  const json* tissue = find_channel(lua_listener.messages, "GAITMON_TISSUE");
  ASSERT_TRUE(tissue);
  EXPECT_EQ((*tissue)["type"], "gaitmon.tissue_t");
  EXPECT_EQ((*tissue)["message"], lua_expected_tissue());
  const json* frame = find_channel(lua_listener.messages, "GAITMON_FRAME");
  const json* raw = find_channel(lua_listener.messages, "GAITMON_RAW");
  ASSERT_TRUE(frame && raw);
  EXPECT_EQ((*frame)["message"]["frame"], 4242);
  EXPECT_EQ((*frame)["message"]["regions"][7]["force_n"], 107.25);
  EXPECT_EQ((*raw)["message"]["sequence"], 4000000000U);
  EXPECT_EQ((*raw)["message"]["bits"].size(), 161U);
  EXPECT_EQ((*raw)["message"]["bits"][3], 111);

  // lcm-logger stops cleanly on SIGINT; its file holds every channel, each payload decoding as
  // its type with the published utime.
  logger.signal(SIGINT);
  ASSERT_EQ(logger.wait(Clock::now() + std::chrono::seconds(5)), 0);
  std::map<std::string, std::vector<test::LogEvent>> logged;
  for (auto& event : test::read_lcm_log(log_path)) logged[event.channel].push_back(event);
  std::set<std::string> logged_channels;
  for (const auto& [channel, events] : logged) logged_channels.insert(channel);
  EXPECT_EQ(logged_channels, kAllChannels);
  const auto decode_last = [&logged](const std::string& channel, auto& message) {
    const auto& data = logged[channel].back().data;
    return message.decode(data.data(), 0, static_cast<int>(data.size())) ==
           static_cast<int>(data.size());
  };
  frame_t f;
  step_t s;
  fit_t t;
  status_t u;
  raw_t r;
  effects_t e;
  tissue_t g;
  ASSERT_TRUE(decode_last("GAITMON_FRAME", f));
  ASSERT_TRUE(decode_last("GAITMON_STEP", s));
  ASSERT_TRUE(decode_last("GAITMON_FIT", t));
  ASSERT_TRUE(decode_last("GAITMON_STATUS", u));
  ASSERT_TRUE(decode_last("GAITMON_RAW", r));
  ASSERT_TRUE(decode_last("GAITMON_EFFECTS", e));
  ASSERT_TRUE(decode_last("GAITMON_TISSUE", g));
  EXPECT_EQ(f.utime, 1763737200123456);
  EXPECT_EQ(s.utime, 1763737200223456);
  EXPECT_EQ(t.utime, 1763737200323456);
  EXPECT_EQ(t.regions[6].status, "fit_failed:no convergence");
  EXPECT_EQ(u.connection, "connected");
  EXPECT_EQ(r.bits.size(), 161U);
  EXPECT_EQ(e.params.size(), 3U);
  EXPECT_EQ(g.regions[4].steps, 76);
  // Event numbers count up from 0 in the order the logger received the messages.
  std::int64_t expected_number = 0;
  for (const auto& event : test::read_lcm_log(log_path)) {
    EXPECT_EQ(event.number, expected_number++);
  }
  lua.signal(SIGTERM);
}

// The spy's JSON lines carry names (feet L/R, kinds, regions) rather than codes.
TEST_F(LcmBus, SpyPrintsEveryMessageAsJson) {
  ChildProcess spy({GAITMON_BINARY, "spy", "--lcm-url", settings().url, "--timeout-s", "60"});
  Listener listener{&spy, [](const json& j) {
                      return j.value("channel", "") == "GAITMON_STATUS" &&
                             j.value("connection", "") == "warmup";
                    }};
  LcmPublisher publisher(settings());
  warm_up(publisher, {&listener}, [] { return true; });
  test::publish_samples(publisher);
  read_messages(listener, 7);
  ASSERT_EQ(listener.messages.size(), 7U);

  const json* frame = find_channel(listener.messages, "GAITMON_FRAME");
  const json* step = find_channel(listener.messages, "GAITMON_STEP");
  const json* fit = find_channel(listener.messages, "GAITMON_FIT");
  const json* status = find_channel(listener.messages, "GAITMON_STATUS");
  const json* raw = find_channel(listener.messages, "GAITMON_RAW");
  ASSERT_TRUE(frame && step && fit && status && raw);

  EXPECT_EQ((*frame)["type"], "frame_t");
  EXPECT_EQ((*frame)["utime"], 1763737200123456);
  EXPECT_EQ((*frame)["foot"], "R");
  EXPECT_EQ((*frame)["frame"], 4242);
  EXPECT_EQ((*frame)["t_s"], 42.42);
  ASSERT_EQ((*frame)["regions"].size(), 8U);
  EXPECT_EQ((*frame)["regions"][0]["region"], "heel");
  EXPECT_EQ((*frame)["regions"][7]["region"], "toes3_5");
  EXPECT_EQ((*frame)["regions"][7]["force_n"], 107.25);
  EXPECT_EQ((*frame)["regions"][5]["ellipse_case"], "long");
  EXPECT_EQ((*frame)["regions"][2]["centre_x_mm"], -12.125);
  EXPECT_EQ((*frame)["regions"][2]["angle_rad"], 0.3 + 0.01 * 2);

  EXPECT_EQ(*step, json({{"channel", "GAITMON_STEP"},
                         {"type", "step_t"},
                         {"utime", 1763737200223456},
                         {"foot", "L"},
                         {"step", 17},
                         {"kind", "toe_off"},
                         {"complete", false},
                         {"frame", 1234},
                         {"t_s", 12.34}}));

  EXPECT_EQ((*fit)["type"], "fit_t");
  EXPECT_EQ((*fit)["foot"], "R");
  EXPECT_EQ((*fit)["step"], 23);
  EXPECT_EQ((*fit)["t_heel_strike_s"], 30.125);
  EXPECT_EQ((*fit)["t_toe_off_s"], 30.75);
  EXPECT_EQ((*fit)["nrmse_total_pct"], 4.5);
  EXPECT_EQ((*fit)["latency_ms"], 1.875);
  EXPECT_EQ((*fit)["effects_inside"], "stress_relaxation,hysteresis");
  EXPECT_EQ((*fit)["effects_utime"], 1763737199000000);
  const FitReport sample = test::sample_fit();
  ASSERT_EQ((*fit)["regions"].size(), 8U);
  for (std::size_t i = 0; i < 8; ++i) {
    const json& g = (*fit)["regions"][i];
    const RegionFitReport& e = sample.regions[i];
    EXPECT_EQ(g["region"], region_name(kRegions[i]));
    EXPECT_EQ(g["status"], e.status);
    EXPECT_EQ(g["kbar_n_per_mm3"], e.kbar_n_per_mm3);
    EXPECT_EQ(g["n"], e.n);
    EXPECT_EQ(g["cbar_ns_per_mm3"], e.cbar_ns_per_mm3);
    EXPECT_EQ(g["m"], e.m);
    EXPECT_EQ(g["se_kbar"], e.se_kbar);
    EXPECT_EQ(g["se_n"], e.se_n);
    EXPECT_EQ(g["se_cbar"], e.se_cbar);
    EXPECT_EQ(g["se_m"], e.se_m);
    EXPECT_EQ(g["se_kbar_total"], e.se_kbar_total);
    EXPECT_EQ(g["se_n_total"], e.se_n_total);
    EXPECT_EQ(g["se_cbar_total"], e.se_cbar_total);
    EXPECT_EQ(g["se_m_total"], e.se_m_total);
    EXPECT_EQ(g["A_mm"], e.A_mm);
    EXPECT_EQ(g["B_mm"], e.B_mm);
    EXPECT_EQ(g["C_mm"], e.C_mm);
    EXPECT_EQ(g["d0_mm"], e.d0_mm);
    EXPECT_EQ(g["nrmse_pct"], e.nrmse_pct);
    EXPECT_EQ(g["m_steps"], e.m_steps);
  }

  json expected_status = lua_expected_status();
  expected_status["channel"] = "GAITMON_STATUS";
  expected_status["type"] = "status_t";
  EXPECT_EQ(*status, expected_status);

  EXPECT_EQ((*raw)["type"], "raw_t");
  EXPECT_EQ((*raw)["foot"], "L");
  EXPECT_EQ((*raw)["sequence"], 4000000000U);
  EXPECT_EQ((*raw)["device_time_us"], 3999999999U);
  ASSERT_EQ((*raw)["bits"].size(), 161U);
  EXPECT_EQ((*raw)["bits"][160], (160 * 37) % 256);

  json expected_effects = lua_expected_effects();
  expected_effects.erase("num_params");
  expected_effects["channel"] = "GAITMON_EFFECTS";
  expected_effects["type"] = "effects_t";
  const json* effects = find_channel(listener.messages, "GAITMON_EFFECTS");
  ASSERT_TRUE(effects);
  EXPECT_EQ(*effects, expected_effects);

  // As the Lua client's, but with the foot and the regions by name.
  json expected_tissue = lua_expected_tissue();
  expected_tissue["foot"] = "L";
  for (json& g : expected_tissue["regions"]) {
    g["region"] = g["region_name"];
    g.erase("region_name");
  }
  expected_tissue["channel"] = "GAITMON_TISSUE";
  expected_tissue["type"] = "tissue_t";
  const json* tissue = find_channel(listener.messages, "GAITMON_TISSUE");
  ASSERT_TRUE(tissue);
  EXPECT_EQ(*tissue, expected_tissue);
}

// Named channels only (by kind here), and --count ends the spy with exit code 0. UDP has no
// handshake, so fits go out until the spy has had its four and exits.
TEST_F(LcmBus, SpyFiltersChannelsAndStopsAtCount) {
  ChildProcess spy({GAITMON_BINARY, "spy", "fit", "--lcm-url", settings().url, "--count", "4",
                    "--timeout-s", "60"});
  LcmPublisher publisher(settings());
  std::optional<int> exit_code;
  const auto give_up = Clock::now() + std::chrono::seconds(20);
  while (!exit_code && Clock::now() < give_up) {
    publisher.publish(test::sample_step());
    publisher.publish(test::sample_fit());
    exit_code = spy.wait(Clock::now() + std::chrono::milliseconds(50));
  }
  ASSERT_EQ(exit_code, 0) << spy.stderr_text(Clock::now() + std::chrono::seconds(1));
  const auto lines = spy.read_rest(ChildProcess::Stdout, Clock::now() + std::chrono::seconds(5));
  ASSERT_EQ(lines.size(), 4U);
  for (const std::string& line : lines) {
    const json m = json::parse(line);
    EXPECT_EQ(m["channel"], "GAITMON_FIT");
    EXPECT_EQ(m["step"], 23);
  }
}

}  // namespace
}  // namespace gaitmon
