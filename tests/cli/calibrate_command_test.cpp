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
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "gaitmon/config.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;

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

// A copy of the shipped config under `dir`/config with `tables` (a calibration.toml) in place of
// its [asymmetry] and [pooling] tables; the path of its gaitmon.toml.
fs::path config_taking(const fs::path& tables, const fs::path& dir) {
  const auto config_dir = dir / "config";
  fs::create_directories(config_dir);
  for (const char* name : {"gaitmon.toml", "insoles.toml", "tissue_seed_appendix_i.toml"}) {
    fs::copy_file(test::source_dir() / "config" / name, config_dir / name,
                  fs::copy_options::overwrite_existing);
  }
  std::string config_text = test::read_text(config_dir / "gaitmon.toml");
  const auto from = config_text.find("[asymmetry]\n");
  const auto to = config_text.find("[wire]\n");
  if (from == std::string::npos || to == std::string::npos || to < from) {
    throw std::runtime_error("the shipped config has no [asymmetry] ... [wire] to replace");
  }
  config_text.replace(from, to - from, test::read_text(tables) + "\n");
  test::write_text(config_dir / "gaitmon.toml", config_text);
  return config_dir / "gaitmon.toml";
}

using PerRegion = std::array<double, kRegionCount>;

// The config's tables of one way of fitting m, by their keys in calibration.json.
std::vector<std::pair<const char*, const PerRegion*>> config_tables(const Config& config,
                                                                    bool shared_m) {
  const ChainSds& chain = shared_m ? config.pooling.m_per_session : config.pooling.per_step;
  const PairSds& pair = shared_m ? config.asymmetry.m_per_session : config.asymmetry.per_step;
  return {{"kbar_chain_sd_pct", &chain.kbar_chain_sd_pct},
          {"n_chain_sd", &chain.n_chain_sd},
          {"cbar_chain_sd_pct", &chain.cbar_chain_sd_pct},
          {"m_chain_sd", &chain.m_chain_sd},
          {"kbar_step_sd_pct", &chain.kbar_step_sd_pct},
          {"n_step_sd", &chain.n_step_sd},
          {"cbar_step_sd_pct", &chain.cbar_step_sd_pct},
          {"m_step_sd", &chain.m_step_sd},
          {"kbar_pair_sd_pct", &pair.kbar_pair_sd_pct},
          {"cbar_pair_sd_pct", &pair.cbar_pair_sd_pct}};
}

// Every entry of one design's tables in calibration.json whose measured value is not the
// config's, as "mode section region key measured (config)".
std::vector<std::string> measured_otherwise(const nlohmann::json& design) {
  std::vector<std::string> otherwise;
  for (const char* mode : {"per_step", "m_per_session"}) {
    for (const char* section : {"pooling", "asymmetry"}) {
      for (const auto& [region, keys] : design.at(mode).at(section).items()) {
        for (const auto& [key, entry] : keys.items()) {
          if (entry.at("measured").is_null()) continue;
          const double measured = entry.at("measured").get<double>();
          const double config = entry.at("config").get<double>();
          if (std::abs(measured - config) > 1e-9) {
            otherwise.push_back(
                fmt::format("{} {} {} {} {} ({})", mode, section, region, key, measured, config));
          }
        }
      }
    }
  }
  return otherwise;
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
  const auto json = nlohmann::json::parse(test::read_text(dir / "out" / "calibration.json"));
  ASSERT_EQ(json.at("designs").size(), 1U);
  const auto& design = json.at("designs").at(0);
  EXPECT_EQ(design.at("sessions").get<int>(), 4);
  EXPECT_EQ(design.at("sizes"), nlohmann::json({"41-42", "45-46"}));
  EXPECT_EQ(design.at("tables"), nlohmann::json({"pooling", "asymmetry"}));
  const auto& heel = design.at("per_step").at("pooling").at("heel").at("kbar_chain_sd_pct");
  EXPECT_EQ(heel.at("samples").get<int>(), 4);
  ASSERT_FALSE(heel.at("measured").is_null());
  // The SD measured brings the RMS of z to at most 1, and without it the steps' scatter alone
  // gives more (the heel's pooled kbar errs by more than its steps scatter: README).
  EXPECT_LE(heel.at("rms_z_measured").get<double>(), 1.0);
  EXPECT_GT(heel.at("rms_z_without").get<double>(), 1.0);
  // Each step's own: a sample per step, and with the chain's SD and its own at most 1.
  const auto& met = design.at("per_step").at("pooling").at("met3_5").at("kbar_step_sd_pct");
  EXPECT_GT(met.at("samples").get<int>(), 20);
  ASSERT_FALSE(met.at("measured").is_null());
  EXPECT_LE(met.at("rms_z_measured").get<double>(), 1.0);

  // The pools weighed each step with the config's step SDs: the command says how many of them
  // these sessions measure otherwise (four sessions cannot reproduce the shipped tables' designs).
  int otherwise = 0;
  for (const char* mode : {"per_step", "m_per_session"}) {
    for (const auto& [region, keys] : design.at(mode).at("pooling").items()) {
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
  EXPECT_NE(test::read_text(dir / "out" / "calibration.toml").find("# Note: " + note),
            std::string::npos);

  const Config config = load_config(config_taking(dir / "out" / "calibration.toml", dir));
  for (const bool shared_m : {false, true}) {
    const auto& mode = design.at(shared_m ? "m_per_session" : "per_step");
    const auto& written = json.at("written").at(shared_m ? "m_per_session" : "per_step");
    for (const auto& [key, values] : config_tables(config, shared_m)) {
      const char* section =
          std::string(key).find("pair") == std::string::npos ? "pooling" : "asymmetry";
      for (Region region : kRegions) {
        const std::string name(region_name(region));
        // One design in one round: what it measured is what is written.
        EXPECT_DOUBLE_EQ((*values)[index_of(region)],
                         expected_value(mode, section, key, name.c_str()))
            << (shared_m ? "m_per_session " : "per_step ") << key << " " << name;
        EXPECT_DOUBLE_EQ((*values)[index_of(region)],
                         written.at(section).at(name).at(key).get<double>())
            << (shared_m ? "m_per_session " : "per_step ") << key << " " << name;
      }
    }
  }
}

// --settle measures again with the tables just measured in the pools until they measure
// themselves. Checked from outside: the plain command, run with the written tables in the config,
// measures every entry as written. A design whose rounds come back to an earlier round's instead
// writes the larger of each entry, with which the plain command measures no entry larger and at
// most the entries the rounds traded otherwise.
// --rasterisation coverage simulates cells that average the pressure and analyses them with
// footprint-mean, as analyze's auto does there: the same design measures other tables than on
// the centre raster, and calibration.json says which raster. They are the footprint_mean tables
// ([pooling.footprint_mean], ...), which calibration.toml gives in their place, the others as the
// config has them.
TEST(CalibrateCommand, OnTheCoverageRasterTheSessionsAreAnalysedWithFootprintMean) {
  const auto dir = test::scratch_dir("calibrate-coverage");
  const std::string design = "--sizes 41-42 --seeds 1-2 --duration 10 --out ";
  int status = -1;
  std::string out = calibrate(design + (dir / "centre").string(), &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_EQ(out.find("coverage raster"), std::string::npos) << out;
  out = calibrate(design + (dir / "coverage").string() + " --rasterisation coverage", &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("placement SD 0 mm; coverage raster, area footprint-mean)"), std::string::npos)
      << out;
  const auto centre = nlohmann::json::parse(test::read_text(dir / "centre" / "calibration.json"));
  const auto coverage =
      nlohmann::json::parse(test::read_text(dir / "coverage" / "calibration.json"));
  EXPECT_EQ(centre.at("designs").at(0).at("rasterisation"), "centre");
  EXPECT_EQ(coverage.at("designs").at(0).at("rasterisation"), "coverage");
  EXPECT_NE(centre.at("designs").at(0).at("per_step"), coverage.at("designs").at(0).at("per_step"));
  for (const char* table : {"\n[pooling.footprint_mean] (each step at its own m): the SD of the",
                            "\n[pooling.footprint_mean.m_per_session] (one m per region over",
                            "\n[asymmetry.footprint_mean] (each step at its own m)"}) {
    EXPECT_NE(out.find(table), std::string::npos) << table << "\n" << out;
  }
  EXPECT_EQ(out.find("\n[pooling] ("), std::string::npos) << out;
  const std::string toml = test::read_text(dir / "coverage" / "calibration.toml");
  EXPECT_NE(toml.find("\n[pooling]\n# no design here simulated cells that read at their centres "
                      "(centre raster): the values of "),
            std::string::npos)
      << toml;
  const Config shipped = load_config(test::source_dir() / "config" / "gaitmon.toml");
  const Config taken = load_config(config_taking(dir / "coverage" / "calibration.toml", dir));
  const auto& mode = coverage.at("designs").at(0).at("per_step");
  const auto& written = coverage.at("written").at("footprint_mean").at("per_step");
  int moved = 0;
  for (Region region : kRegions) {
    const std::size_t ri = index_of(region);
    const std::string name(region_name(region));
    EXPECT_EQ(taken.pooling.per_step.kbar_chain_sd_pct[ri],
              shipped.pooling.per_step.kbar_chain_sd_pct[ri])
        << name;
    EXPECT_EQ(taken.asymmetry.per_step.cbar_pair_sd_pct[ri],
              shipped.asymmetry.per_step.cbar_pair_sd_pct[ri])
        << name;
    const double kbar = taken.pooling_footprint_mean.per_step.kbar_chain_sd_pct[ri];
    EXPECT_DOUBLE_EQ(kbar, expected_value(mode, "pooling", "kbar_chain_sd_pct", name.c_str()))
        << name;
    EXPECT_DOUBLE_EQ(kbar, written.at("pooling").at(name).at("kbar_chain_sd_pct").get<double>())
        << name;
    EXPECT_DOUBLE_EQ(taken.asymmetry_footprint_mean.per_step.cbar_pair_sd_pct[ri],
                     expected_value(mode, "asymmetry", "cbar_pair_sd_pct", name.c_str()))
        << name;
    if (kbar != shipped.pooling_footprint_mean.per_step.kbar_chain_sd_pct[ri]) ++moved;
  }
  EXPECT_GT(moved, 0) << "two sessions measure the shipped tables otherwise";
  out = calibrate(design + (dir / "bad").string() + " --rasterisation cells", &status);
  EXPECT_EQ(status, 2) << out;
  EXPECT_FALSE(fs::exists(dir / "bad"));
}

TEST(CalibrateCommand, SettleMeasuresAgainWithItsOwnTablesUntilTheyMeasureThemselves) {
  const struct {
    const char* design;
    const char* outcome;
  } cases[] = {{"--sizes 41-42 --seeds 1-2 --duration 10", "nothing_moved"},
               {"--sizes 41-42,45-46 --seeds 1-2 --duration 10", "cycle"}};
  for (const auto& c : cases) {
    SCOPED_TRACE(c.design);
    const auto dir = test::scratch_dir(std::string("calibrate-settle-") + c.outcome);
    int status = -1;
    const std::string out =
        calibrate(std::string(c.design) + " --settle --out " + (dir / "settled").string(), &status);
    ASSERT_EQ(status, 0) << out;
    const auto json = nlohmann::json::parse(test::read_text(dir / "settled" / "calibration.json"));
    const auto& settle = json.at("settle");
    ASSERT_EQ(settle.at("outcome").get<std::string>(), c.outcome) << out;
    const auto moved = settle.at("moved").get<std::vector<int>>();
    ASSERT_EQ(moved.size(), settle.at("rounds").get<std::size_t>());
    ASSERT_GE(moved.size(), 2U);
    // The first round moves the shipped tables (measured on designs a hundred times larger),
    // and a round's line says how many entries moved.
    EXPECT_GT(moved.front(), 20);
    for (std::size_t round = 0; round < moved.size(); ++round) {
      const auto at = out.find(fmt::format("round {}: simulated and analysed in", round + 1));
      ASSERT_NE(at, std::string::npos) << out;
      const std::string line = out.substr(at, out.find('\n', at) - at);
      EXPECT_NE(line.find(fmt::format("; {} of the tables' entries moved", moved[round])),
                std::string::npos)
          << line;
      // A few entries that moved are named, each with its value before and after.
      const bool named = moved[round] > 0 && moved[round] <= 6;
      EXPECT_EQ(line.find(" -> ") != std::string::npos, named) << line;
      if (named) {
        EXPECT_NE(line.find("moved: ["), std::string::npos) << line;
      }
    }
    EXPECT_NE(out.find("\ncalibrate: " + settle.at("note").get<std::string>()), std::string::npos)
        << out;
    EXPECT_NE(test::read_text(dir / "settled" / "calibration.toml")
                  .find("# Note: " + settle.at("note").get<std::string>()),
              std::string::npos);

    const auto config = config_taking(dir / "settled" / "calibration.toml", dir);
    std::string again_out;
    status = test::run_command(test::gaitmon_binary().string() + " --config " + config.string() +
                                   " calibrate " + c.design + " --out " + (dir / "again").string(),
                               &again_out);
    ASSERT_EQ(status, 0) << again_out;
    const auto again = nlohmann::json::parse(test::read_text(dir / "again" / "calibration.json"));
    ASSERT_EQ(again.at("designs").size(), 1U);
    const std::vector<std::string> otherwise = measured_otherwise(again.at("designs").at(0));
    if (std::string(c.outcome) == "nothing_moved") {
      EXPECT_EQ(moved.back(), 0);
      EXPECT_TRUE(otherwise.empty()) << fmt::format("{}", fmt::join(otherwise, "\n"));
      EXPECT_EQ(json.at("step_sds_measured_otherwise").get<int>(), 0);
      continue;
    }
    const int from = settle.at("cycle_from_round").get<int>();
    EXPECT_GE(from, 1);
    EXPECT_LT(from, static_cast<int>(moved.size()));
    const std::string note = settle.at("note").get<std::string>();
    const auto trading_at = note.find(" entries trading");
    ASSERT_NE(trading_at, std::string::npos) << note;
    const int trading = std::stoi(note.substr(note.rfind(' ', trading_at - 1) + 1));
    EXPECT_GT(trading, 0);
    EXPECT_LE(otherwise.size(), static_cast<std::size_t>(trading))
        << fmt::format("{}", fmt::join(otherwise, "\n"));
    for (const char* mode : {"per_step", "m_per_session"}) {
      for (const char* section : {"pooling", "asymmetry"}) {
        for (const auto& [region, keys] : again.at("designs").at(0).at(mode).at(section).items()) {
          for (const auto& [key, entry] : keys.items()) {
            if (entry.at("measured").is_null()) continue;
            EXPECT_LE(entry.at("measured").get<double>(), entry.at("config").get<double>() + 1e-9)
                << mode << " " << section << " " << region << " " << key;
          }
        }
      }
    }
  }
}

// With a designs file each table takes, entry by entry, the largest of the designs that measure
// it (the config's where none did), and a design that does not measure a table has none of it.
TEST(CalibrateCommand, ADesignsFileGivesEachTableTheLargestOfTheDesignsThatMeasureIt) {
  const auto dir = test::scratch_dir("calibrate-designs");
  const auto designs =
      test::write_text(dir / "designs.toml",
                       "[[design]]\ntables = [\"pooling\", \"asymmetry\"]\nsizes = [\"41-42\"]\n"
                       "seeds = [1, 2]\nduration_s = 10\nbody_mass_kg = [50, 90]\n\n"
                       "[[design]]\ntables = [\"pooling\"]\nsizes = [\"45-46\"]\nseeds = [1, 2]\n"
                       "duration_s = 10\nbody_mass_kg = [60, 60]\nnoise_sd_bits = 1.0\n");
  int status = -1;
  const std::string out =
      calibrate("--designs " + designs.string() + " --out " + (dir / "out").string(), &status);
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("calibrate: design 1 of 2 ([pooling] and [asymmetry]): 2 simulated "
                     "sessions of 10 s (sizes 41-42; seeds 1-2; body mass 50-90 kg; noise 0.5"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("calibrate: design 2 of 2 ([pooling]): 2 simulated sessions of 10 s (sizes "
                     "45-46; seeds 1-2; body mass 60 kg; noise 1 bits"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("\nThe tables written (the larger of each entry over the designs that "
                     "measure it):\n"),
            std::string::npos)
      << out;
  const auto json = nlohmann::json::parse(test::read_text(dir / "out" / "calibration.json"));
  ASSERT_EQ(json.at("designs").size(), 2U);
  const auto& one = json.at("designs").at(0);
  const auto& two = json.at("designs").at(1);
  EXPECT_EQ(two.at("tables"), nlohmann::json({"pooling"}));
  EXPECT_FALSE(two.at("per_step").contains("asymmetry"));
  EXPECT_FALSE(two.at("m_per_session").contains("asymmetry"));
  EXPECT_EQ(two.at("noise_sd_bits").get<double>(), 1.0);

  const Config config = load_config(config_taking(dir / "out" / "calibration.toml", dir));
  int larger_from_two = 0;
  for (const bool shared_m : {false, true}) {
    const char* mode = shared_m ? "m_per_session" : "per_step";
    for (const auto& [key, values] : config_tables(config, shared_m)) {
      const bool is_pair = std::string(key).find("pair") != std::string::npos;
      const char* section = is_pair ? "asymmetry" : "pooling";
      for (Region region : kRegions) {
        const std::string name(region_name(region));
        SCOPED_TRACE(fmt::format("{} {} {}", mode, key, name));
        const auto& a = one.at(mode).at(section).at(name).at(key);
        double expected = a.at("config").get<double>();
        std::optional<double> largest;
        if (!a.at("measured").is_null()) largest = a.at("measured").get<double>();
        if (!is_pair) {
          const auto& b = two.at(mode).at(section).at(name).at(key);
          if (!b.at("measured").is_null()) {
            const double from_two = b.at("measured").get<double>();
            if (from_two > largest.value_or(-1.0)) ++larger_from_two;
            largest = std::max(largest.value_or(from_two), from_two);
          }
        }
        if (largest) expected = *largest;
        EXPECT_DOUBLE_EQ((*values)[index_of(region)], expected);
        EXPECT_DOUBLE_EQ(json.at("written").at(mode).at(section).at(name).at(key).get<double>(),
                         expected);
      }
    }
  }
  // Both designs give some entries: the second's larger ones are in the tables written.
  EXPECT_GT(larger_from_two, 0);
}

TEST(CalibrateCommand, AMalformedDesignIsAUsageErrorThatSaysWhyAndWritesNothing) {
  const auto dir = test::scratch_dir("calibrate-bad");
  const std::string shipped_designs =
      (test::source_dir() / "config" / "calibration_designs.toml").string();
  const std::string bad_designs =
      test::write_text(dir / "bad-designs.toml", "[[design]]\ntables = [\"pool\"]\n").string();
  const struct {
    std::string args;
    const char* says;
  } cases[] = {
      {"--seeds 5-1", "seeds: the first (5) is after the last (1)"},
      {"--seeds one", "--seeds: 'one': expected a number or FIRST-LAST"},
      {"--seeds -3", "--seeds: '-3': expected a number or FIRST-LAST"},
      {"--body-mass 90-50", "body mass must be 0 < min <= max <= 300 kg, got 90 to 50"},
      {"--body-mass 60-nan", "--body-mass: '60-nan': expected a number or FIRST-LAST"},
      {"--sizes 41-42,40-41", "--sizes: 40-41 not in"},
      {"--duration 2", "--duration"},
      {"--max-rounds 4", "--max-rounds requires --settle"},
      {"--settle --max-rounds 1", "--max-rounds: Value 1 not in range 2 to 50"},
      {"--designs no-such-designs.toml", "--designs: File does not exist: no-such-designs.toml"},
      {"--designs " + shipped_designs + " --seeds 1-2", "--seeds excludes --designs"},
      {"--designs " + bad_designs,
       R"(bad-designs.toml: design[1].tables: expected "pooling" or "asymmetry" (line 2))"},
  };
  for (const auto& c : cases) {
    int status = -1;
    const std::string out = calibrate(c.args + " --out " + (dir / "out").string(), &status);
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
    EXPECT_TRUE(started) << test::read_text(log);
    EXPECT_EQ(ended, pid) << "still running 120 s on";
    EXPECT_TRUE(WIFSIGNALED(wstatus) && WTERMSIG(wstatus) == signal) << test::read_text(log);
    EXPECT_TRUE(fs::is_empty(tmp)) << test::read_text(log);
    EXPECT_FALSE(fs::exists(dir / "out" / "calibration.json"));
    EXPECT_NE(test::read_text(log).find(fmt::format("calibrate: stopped by {}; nothing written",
                                                    signal == SIGINT ? "SIGINT" : "SIGTERM")),
              std::string::npos)
        << test::read_text(log);
  }
}

TEST(CalibrateCommand, HelpNamesTheDesignsOptionsAndTheirDefaults) {
  int status = -1;
  const std::string out = calibrate("--help", &status);
  ASSERT_EQ(status, 0) << out;
  for (const char* option :
       {"--sizes", "--seeds TEXT=1-20", "--duration", "--body-mass TEXT=50-90", "--noise",
        "--max-bias", "--placement-sd", "--rasterisation", "--designs", "--settle",
        "--max-rounds UINT:INT in [2 - 50]=10", "--out"}) {
    EXPECT_NE(out.find(option), std::string::npos) << option << "\n" << out;
  }
}

}  // namespace
}  // namespace gaitmon
