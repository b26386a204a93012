// What the tests of the live commands share: the config they run with, a Lua client on the bus,
// analyze's CSVs, and the comparisons of what they produced (fits, recordings) with the truth.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "gaitmon/session.hpp"
#include "gaitmon/types.hpp"
#include "lcm/bus_support.hpp"
#include "monitor_support.hpp"
#include "test_support.hpp"

namespace gaitmon::test {

namespace fs = std::filesystem;

inline std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> fields;
  std::stringstream in(line);
  std::string field;
  while (std::getline(in, field, ',')) fields.push_back(field);
  if (!line.empty() && line.back() == ',') fields.emplace_back();
  return fields;
}

// A CSV of `gaitmon analyze` as rows of column -> text.
inline std::vector<std::map<std::string, std::string>> read_csv(const fs::path& path) {
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

// regions.csv of `gaitmon analyze`, keyed by foot, step and region.
inline std::map<std::tuple<std::string, int, std::string>, std::map<std::string, std::string>>
read_regions_csv(const fs::path& path) {
  std::map<std::tuple<std::string, int, std::string>, std::map<std::string, std::string>> rows;
  for (auto& row : read_csv(path)) rows[{row["foot"], std::stoi(row["step"]), row["region"]}] = row;
  return rows;
}

// analyze prints 4-6 significant digits; LCM carries full doubles.
inline void expect_printed(double value, const std::string& printed, const std::string& what) {
  const double expected = std::stod(printed);
  EXPECT_NEAR(value, expected, 1e-3 * std::abs(expected) + 1e-12) << what;
}

// The shipped config with room for every step and frame: the comparison needs all of them,
// whatever the load on the machine. Per-frame reports are off: UDP has no flow control, and
// 800 frame messages a second (4 x real time) overflow a listener's socket buffer when the
// machine is busy, taking step and fit messages with them. The comparison needs only steps and
// fits; frame_t crosses the real bus in tests/lcm/lcm_bus_test.cpp.
// `changes` are further (text, replacement) pairs for gaitmon.toml.
inline fs::path roomy_config(const fs::path& dir,
                             const std::vector<std::pair<std::string, std::string>>& changes = {}) {
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
  for (const auto& [from, to] : changes) set(from, to);
  test::write_text(dir / "gaitmon.toml", toml);
  return dir / "gaitmon.toml";
}

/// The Lua client built from the lcm-gen types (tests/lcm/subscriber.lua) on `bus`, printing
/// fits and statuses as JSON lines; returned once it listens, or null after a failure.
inline std::unique_ptr<ChildProcess> fit_and_status_client(const Bus& bus) {
  auto lua = std::make_unique<ChildProcess>(std::vector<std::string>{
      "lua5.2", source_dir().string() + "/tests/lcm/subscriber.lua", "--url", bus.url, "--types",
      GAITMON_LCM_LUA_DIR, "--timeout-s", "300", "GAITMON_FIT=fit_t", "GAITMON_STATUS=status_t"});
  if (lua->read_until(ChildProcess::Stdout, "ready",
                      std::chrono::steady_clock::now() + std::chrono::seconds(20))
          .empty()) {
    ADD_FAILURE() << "the Lua client did not start";
    return nullptr;
  }
  return lua;
}

/// Fits as a subscriber decoded them (fit_t as JSON) against analyze's regions.csv: every fit a
/// row per region, with the same status and parameters.
inline void expect_fits_match_regions(const std::vector<nlohmann::json>& fits,
                                      const fs::path& regions_csv, std::size_t min_fits) {
  using nlohmann::json;
  const auto regions = read_regions_csv(regions_csv);
  ASSERT_GE(fits.size(), min_fits);
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
}

/// A recording against the session a device streamed: the same insole, and every frame with the
/// same foot, time and readings. Returns the recording's header for the caller's own checks.
inline SessionHeader expect_recording_of(const fs::path& recording, const fs::path& session) {
  SessionHeader original_header;
  SessionHeader recorded_header;
  const std::vector<Frame> original = file_frames(session, &original_header);
  const std::vector<Frame> recorded = file_frames(recording, &recorded_header);
  EXPECT_EQ(recorded_header.insole_size, original_header.insole_size);
  EXPECT_EQ(recorded_header.sensors, original_header.sensors);
  EXPECT_EQ(recorded.size(), original.size());
  for (std::size_t i = 0; i < std::min(original.size(), recorded.size()); ++i) {
    if (recorded[i].foot == original[i].foot && recorded[i].t_s == original[i].t_s &&
        recorded[i].bits == original[i].bits)
      continue;
    ADD_FAILURE() << "recorded frame " << i << " (at " << recorded[i].t_s
                  << " s) differs from the streamed one in foot, time or readings";
    break;
  }
  return recorded_header;
}

}  // namespace gaitmon::test
