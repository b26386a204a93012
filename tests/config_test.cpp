// Config loading: the shipped files, their agreement with the seed data, and every refusal rule.
#include "gaitmon/config.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "gaitmon/error.hpp"
#include "gaitmon/insole.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

constexpr const char* kMain = "gaitmon.toml";
constexpr const char* kInsoles = "insoles.toml";
constexpr const char* kTissue = "tissue_seed_appendix_i.toml";

fs::path shipped_config_path() {
  return test::source_dir() / "config" / kMain;
}

using test::read_text;

// The three shipped files copied into a fresh folder, so that one can be edited.
fs::path copy_config(const std::string& name) {
  const fs::path dir = test::scratch_dir("config-" + name);
  for (const char* file : {kMain, kInsoles, kTissue}) {
    fs::copy_file(test::source_dir() / "config" / file, dir / file);
  }
  return dir;
}

using Edit = std::function<void(std::string&)>;

// Replaces the first `from` after `anchor`; both must exist, or the test itself is wrong.
Edit replace(std::string anchor, std::string from, std::string to) {
  return [=](std::string& text) {
    const auto at = text.find(anchor);
    if (at == std::string::npos) throw std::logic_error("anchor not found: " + anchor);
    const auto pos = text.find(from, at);
    if (pos == std::string::npos) throw std::logic_error("text not found: " + from);
    text.replace(pos, from.size(), to);
  };
}

Edit replace(std::string from, std::string to) {
  return replace(from, from, std::move(to));
}

// The heel's value of table `key` after `anchor`, whatever it was.
Edit set_heel(std::string anchor, std::string key, std::string value) {
  return [=](std::string& text) {
    const auto at = text.find(anchor);
    if (at == std::string::npos) throw std::logic_error("anchor not found: " + anchor);
    const std::string heel = key + " = { heel = ";
    const auto pos = text.find(heel, at);
    if (pos == std::string::npos) throw std::logic_error("text not found: " + heel);
    const auto from = pos + heel.size();
    text.replace(from, text.find(',', from) - from, value);
  };
}

Edit prepend(std::string line) {
  return [=](std::string& text) { text.insert(0, line); };
}

Edit append(std::string lines) {
  return [=](std::string& text) { text += lines; };
}

Edit truncate_at(std::string anchor) {
  return [=](std::string& text) {
    const auto at = text.find(anchor);
    if (at == std::string::npos) throw std::logic_error("anchor not found: " + anchor);
    text.erase(at);
  };
}

Edit erase_from_to(std::string first, std::string until) {
  return [=](std::string& text) {
    const auto a = text.find(first);
    const auto b = text.find(until, a);
    if (a == std::string::npos || b == std::string::npos) throw std::logic_error("not found");
    text.erase(a, b - a);
  };
}

void edit_file(const fs::path& path, const Edit& edit) {
  std::string text = read_text(path);
  edit(text);
  test::write_text(path, text);
}

TEST(Config, ShippedConfigHasTheDocumentedDefaults) {
  const Config config = load_config(shipped_config_path());
  EXPECT_EQ(config.source, shipped_config_path());
  EXPECT_DOUBLE_EQ(config.sample_rate_hz, 100.0);
  EXPECT_DOUBLE_EQ(config.sensor.width_mm, 7.5);
  EXPECT_DOUBLE_EQ(config.sensor.height_mm, 15.0);
  EXPECT_DOUBLE_EQ(config.sensor.pitch_x_mm, 7.5);
  EXPECT_DOUBLE_EQ(config.sensor.pitch_y_mm, 15.0);
  EXPECT_EQ(config.sensor.alignment, RowAlignment::Centred);
  EXPECT_DOUBLE_EQ(config.calibration.full_scale_bits, 255.0);
  EXPECT_DOUBLE_EQ(config.calibration.full_scale_n_per_cm2, 64.0);
  EXPECT_DOUBLE_EQ(config.sensor_creep.gain, 0.0) << "no creep undone unless measured";
  EXPECT_DOUBLE_EQ(config.sensor_creep.tau_s, 1.0);
  EXPECT_EQ(config.segmentation.event_threshold_bits, 142);
  EXPECT_EQ(config.segmentation.debounce_frames, 5);
  EXPECT_EQ(config.segmentation.swing_window_frames, 5);
  EXPECT_DOUBLE_EQ(config.segmentation.threshold_noise_sds, 4.0);
  EXPECT_DOUBLE_EQ(config.segmentation.max_gap_s, 0.055);
  // Seed Table 2.
  const std::vector<double> threshold_pct{0.2, 0.2, 0.1, 0.1, 0.2, 0.2};
  for (InsoleSize size : kInsoleSizes) {
    EXPECT_EQ(config.insole(size).size, size);
    EXPECT_DOUBLE_EQ(config.insole(size).adaptive_threshold_pct, threshold_pct[index_of(size)])
        << insole_size_name(size);
  }
}

TEST(Config, NewtonsPerBitOfTheShippedCalibration) {
  const Config config = load_config(shipped_config_path());
  // 64 N/cm^2 / 255 bits x 1.125 cm^2 = 0.282353 N, worked out by hand.
  EXPECT_NEAR(config.calibration.newtons_per_bit(112.5), 0.28235, 1e-5);
  EXPECT_DOUBLE_EQ(config.sensor.area_mm2(), 112.5);
  // The seed's 142-bit event threshold is 40 N (142 x 0.28235 = 40.09).
  EXPECT_NEAR(config.segmentation.event_threshold_bits * 0.28235, 40.0, 0.1);
}

struct CsvSensor {
  std::size_t index;
  int row;
  int number_in_row;
  std::string region;
};

std::map<std::string, std::vector<CsvSensor>> read_region_csv(const fs::path& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "insole_size,sensor_index,row,number_in_row,region");
  std::map<std::string, std::vector<CsvSensor>> out;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    std::vector<std::string> cells;
    std::stringstream fields(line);
    std::string cell;
    while (std::getline(fields, cell, ',')) cells.push_back(cell);
    EXPECT_EQ(cells.size(), 5u) << line;
    if (cells.size() != 5) continue;
    out[cells[0]].push_back(
        {std::stoul(cells[1]) - 1, std::stoi(cells[2]), std::stoi(cells[3]), cells[4]});
  }
  return out;
}

TEST(Config, InsoleLayoutsEqualTheSeedRegionCsv) {
  const fs::path csv = test::shared_dir() / "seed-data" / "insole_sensor_regions.csv";
  if (!fs::exists(csv)) GTEST_SKIP() << "seed data missing: " << csv;
  const auto expected = read_region_csv(csv);
  const Config config = load_config(shipped_config_path());
  // Appendix B's counts (Table 1 states 130 and 162 for 41-42 and 45-46).
  const std::vector<std::size_t> counts{93, 107, 116, 129, 151, 161};
  for (InsoleSize size : kInsoleSizes) {
    const std::string name(insole_size_name(size));
    SCOPED_TRACE(name);
    const InsoleLayout layout(config.insole(size), config.sensor);
    ASSERT_TRUE(expected.contains(name));
    const auto& rows = expected.at(name);
    EXPECT_EQ(layout.sensor_count(), counts[index_of(size)]);
    ASSERT_EQ(layout.sensor_count(), rows.size());
    for (std::size_t i = 0; i < rows.size(); ++i) {
      const Sensor& s = layout.sensor(i);
      EXPECT_EQ(s.index, rows[i].index);
      EXPECT_EQ(s.row, rows[i].row) << "sensor " << i;
      EXPECT_EQ(s.number_in_row, rows[i].number_in_row) << "sensor " << i;
      EXPECT_EQ(region_name(s.region), rows[i].region) << "sensor " << i;
    }
  }
}

TEST(Config, SeedTissueMatchesAppendixI) {
  const Config config = load_config(shipped_config_path());
  const SeedTissueStats& heel = config.tissue(InsoleSize::S37_38, Region::Heel);
  EXPECT_DOUBLE_EQ(heel.mean.d0_mm, 16.4);
  EXPECT_DOUBLE_EQ(heel.sd.d0_mm, 0.9);
  EXPECT_DOUBLE_EQ(heel.mean.A_mm, 80.2);
  EXPECT_DOUBLE_EQ(heel.sd.B_mm, 4.6);
  EXPECT_DOUBLE_EQ(heel.mean.C_mm, 69.9);
  EXPECT_DOUBLE_EQ(heel.mean.kbar_n_per_mm3, 0.117);
  EXPECT_DOUBLE_EQ(heel.sd.kbar_n_per_mm3, 0.027);
  EXPECT_DOUBLE_EQ(heel.mean.cbar_ns_per_mm3, 0.011);
  EXPECT_DOUBLE_EQ(heel.mean.n, 0.294);
  EXPECT_DOUBLE_EQ(heel.sd.n, 0.116);
  EXPECT_DOUBLE_EQ(heel.mean.m, 1.18);
  EXPECT_DOUBLE_EQ(heel.nrmse_pct_mean, 25.5);
  EXPECT_DOUBLE_EQ(heel.nrmse_pct_sd, 4.2);
  // An SD of zero is allowed (35-36 heel c-bar 0.010 (0.000)).
  EXPECT_DOUBLE_EQ(config.tissue(InsoleSize::S35_36, Region::Heel).mean.cbar_ns_per_mm3, 0.010);
  EXPECT_DOUBLE_EQ(config.tissue(InsoleSize::S35_36, Region::Heel).sd.cbar_ns_per_mm3, 0.0);
  // Printed inline as "9.0 (3.0)" in the seed.
  EXPECT_DOUBLE_EQ(config.tissue(InsoleSize::S43_44, Region::MidfootPosterior).nrmse_pct_mean, 9.0);
  EXPECT_DOUBLE_EQ(config.tissue(InsoleSize::S43_44, Region::MidfootPosterior).nrmse_pct_sd, 3.0);
  EXPECT_DOUBLE_EQ(config.tissue(InsoleSize::S45_46, Region::Met1_2).mean.C_mm, 154.1);
  EXPECT_DOUBLE_EQ(config.tissue(InsoleSize::S45_46, Region::Toes3_5).mean.A_mm, 76.7);
}

TEST(Config, SeedTissueEqualsTheAppendixICsv) {
  const fs::path csv = test::shared_dir() / "seed-data" / "seed_table_I_results.csv";
  if (!fs::exists(csv)) GTEST_SKIP() << "seed data missing: " << csv;
  const Config config = load_config(shipped_config_path());
  std::ifstream in(csv);
  std::string line;
  std::getline(in, line);
  ASSERT_EQ(line, "insole_size,region,param,mean,sd");
  int checked = 0;
  while (std::getline(in, line)) {
    std::vector<std::string> c;
    std::stringstream fields(line);
    std::string cell;
    while (std::getline(fields, cell, ',')) c.push_back(cell);
    ASSERT_EQ(c.size(), 5u) << line;
    const auto size = parse_insole_size(c[0]);
    const auto region = parse_region(c[1]);
    ASSERT_TRUE(size && region) << line;
    const SeedTissueStats& t = config.tissue(*size, *region);
    const std::map<std::string, std::pair<double, double>> by_param{
        {"d0", {t.mean.d0_mm, t.sd.d0_mm}},
        {"A", {t.mean.A_mm, t.sd.A_mm}},
        {"B", {t.mean.B_mm, t.sd.B_mm}},
        {"C", {t.mean.C_mm, t.sd.C_mm}},
        {"k", {t.mean.kbar_n_per_mm3, t.sd.kbar_n_per_mm3}},
        {"c", {t.mean.cbar_ns_per_mm3, t.sd.cbar_ns_per_mm3}},
        {"n", {t.mean.n, t.sd.n}},
        {"m", {t.mean.m, t.sd.m}},
        {"NRMSE", {t.nrmse_pct_mean, t.nrmse_pct_sd}}};
    ASSERT_TRUE(by_param.contains(c[2])) << line;
    EXPECT_DOUBLE_EQ(by_param.at(c[2]).first, std::stod(c[3])) << line;
    EXPECT_DOUBLE_EQ(by_param.at(c[2]).second, std::stod(c[4])) << line;
    ++checked;
  }
  EXPECT_EQ(checked, 6 * 8 * 9);
}

TEST(Config, AcceptsBoundaryValuesAndAnAbsoluteInsolesPath) {
  const fs::path dir = copy_config("boundaries");
  const fs::path elsewhere = test::scratch_dir("config-boundaries-elsewhere");
  fs::rename(dir / kInsoles, elsewhere / "layouts.toml");
  const fs::path main = dir / kMain;
  edit_file(main, replace("insoles_file = \"insoles.toml\"",
                          "insoles_file = \"" + (elsewhere / "layouts.toml").string() + "\""));
  edit_file(main, replace("sample_rate_hz = 100", "sample_rate_hz = 10000"));
  edit_file(main, replace("pitch_x_mm = 7.5", "pitch_x_mm = 10"));
  edit_file(main, replace("pitch_y_mm = 15.0", "pitch_y_mm = 20"));
  edit_file(main, replace("row_alignment = \"centred\"", "row_alignment = \"medial\""));
  edit_file(main, replace("[sensor_creep]", "\ngain = 0\n", "\ngain = 2\n"));
  edit_file(main, replace("[sensor_creep]", "tau_s = 1.0", "tau_s = 60"));
  edit_file(main, replace("event_threshold_bits = 142", "event_threshold_bits = 41055"));
  edit_file(main, replace("debounce_frames = 5", "debounce_frames = 100"));
  edit_file(main, replace("swing_window_frames = 5", "swing_window_frames = 1"));
  edit_file(main, replace("threshold_noise_sds = 4", "threshold_noise_sds = 0"));
  // 1.5 periods at 10 kHz are 0.00015 s.
  edit_file(main, replace("max_gap_s = 0.055", "max_gap_s = 0.0002"));
  edit_file(elsewhere / "layouts.toml", replace("[sizes.\"37-38\"]", "adaptive_threshold_pct = 0.2",
                                                "adaptive_threshold_pct = 100"));
  const Config config = load_config(main);
  EXPECT_DOUBLE_EQ(config.sample_rate_hz, 10000.0);
  EXPECT_DOUBLE_EQ(config.sensor.pitch_x_mm, 10.0);
  EXPECT_DOUBLE_EQ(config.sensor.pitch_y_mm, 20.0);
  EXPECT_EQ(config.sensor.alignment, RowAlignment::Medial);
  EXPECT_DOUBLE_EQ(config.sensor_creep.gain, 2.0);
  EXPECT_DOUBLE_EQ(config.sensor_creep.tau_s, 60.0);
  EXPECT_EQ(config.segmentation.event_threshold_bits, 41055);
  EXPECT_EQ(config.segmentation.debounce_frames, 100);
  EXPECT_EQ(config.segmentation.swing_window_frames, 1);
  EXPECT_EQ(config.segmentation.threshold_noise_sds, 0.0);
  EXPECT_DOUBLE_EQ(config.segmentation.max_gap_s, 0.0002);
  EXPECT_DOUBLE_EQ(config.insole(InsoleSize::S37_38).adaptive_threshold_pct, 100.0);
}

TEST(Config, DefaultConfigPathHonoursTheEnvironment) {
  const char* before = std::getenv("GAITMON_CONFIG");
  const std::optional<std::string> saved =
      before ? std::optional<std::string>(before) : std::nullopt;
  ::unsetenv("GAITMON_CONFIG");
  EXPECT_EQ(default_config_path(), shipped_config_path());
  ::setenv("GAITMON_CONFIG", "", 1);
  EXPECT_EQ(default_config_path(), shipped_config_path());
  ::setenv("GAITMON_CONFIG", "/somewhere/else.toml", 1);
  EXPECT_EQ(default_config_path(), fs::path("/somewhere/else.toml"));
  if (saved) {
    ::setenv("GAITMON_CONFIG", saved->c_str(), 1);
  } else {
    ::unsetenv("GAITMON_CONFIG");
  }
}

TEST(Config, RefusesAMissingMainFile) {
  const fs::path dir = test::scratch_dir("config-absent");
  try {
    load_config(dir / "absent.toml");
    FAIL() << "no ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.file(), (dir / "absent.toml").string());
    EXPECT_EQ(e.key(), "(file)");
    EXPECT_THAT(e.reason(), HasSubstr("no such file"));
  }
}

// One refusal rule: which file to edit, how, and what the error must name.
struct Refusal {
  std::string name;
  std::string file;
  Edit edit;
  std::string key;
  std::string reason;  ///< a part of the reason
};

void PrintTo(const Refusal& r, std::ostream* os) {
  *os << r.name;
}

// For tests that list their own refusals rather than adding to kRefusals.
void expect_refusals(const std::vector<Refusal>& cases) {
  for (const Refusal& c : cases) {
    const fs::path dir = copy_config(c.name);
    edit_file(dir / c.file, c.edit);
    try {
      load_config(dir / kMain);
      ADD_FAILURE() << c.name << ": no ConfigError";
    } catch (const ConfigError& e) {
      EXPECT_EQ(e.file(), (dir / c.file).string()) << c.name;
      EXPECT_EQ(e.key(), c.key) << c.name;
      EXPECT_THAT(e.reason(), HasSubstr(c.reason)) << c.name;
    }
  }
}

class ConfigRefusal : public ::testing::TestWithParam<Refusal> {};

TEST_P(ConfigRefusal, ThrowsConfigErrorNamingFileAndKey) {
  const Refusal& r = GetParam();
  const fs::path dir = copy_config(r.name);
  edit_file(dir / r.file, r.edit);
  const std::string file = (dir / r.file).string();
  try {
    load_config(dir / kMain);
    FAIL() << "no ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.file(), file);
    EXPECT_EQ(e.key(), r.key);
    EXPECT_THAT(e.reason(), HasSubstr(r.reason));
    EXPECT_THAT(e.what(), HasSubstr(file));
    EXPECT_THAT(e.what(), HasSubstr(r.key));
  }
}

const char* const kSize37 = "[sizes.\"37-38\"]";
const char* const kRegions37 = "[sizes.\"37-38\".regions]";
const char* const kHeel37 = "[sizes.\"37-38\".heel]";

// clang-format off
const Refusal kRefusals[] = {
    // The main file.
    {"MainSyntaxError", kMain, prepend("oops = = 1\n"), "(syntax)", "line 1, column"},
    {"UnknownTopLevelKey", kMain, prepend("colour = \"red\"\n"), "colour", "unknown key"},
    {"UnknownKeyInSection", kMain, replace("[sensor]\n", "[sensor]\nwidht_mm = 7.5\n"),
     "sensor.widht_mm", "unknown key"},
    {"UnknownSection", kMain, append("\n[fitting]\nmax_iterations = 50\n"), "fitting", "unknown key"},
    {"MissingKey", kMain, replace("debounce_frames = 5\n", ""), "segmentation.debounce_frames",
     "missing"},
    {"MissingSection", kMain, erase_from_to("[calibration]", "[segmentation]"), "calibration",
     "missing"},
    {"SectionNotATable", kMain, replace("[sensor]\n", "sensor = 1\n[sensor_moved]\n"), "sensor",
     "expected a table"},
    {"WrongTypeString", kMain, replace("row_alignment = \"centred\"", "row_alignment = 1"),
     "sensor.row_alignment", "expected a string, got an integer"},
    {"WrongTypeInteger", kMain, replace("event_threshold_bits = 142", "event_threshold_bits = 142.0"),
     "segmentation.event_threshold_bits", "expected an integer, got a floating-point number"},
    {"WrongTypeNumber", kMain, replace("sample_rate_hz = 100", "sample_rate_hz = \"100\""),
     "sample_rate_hz", "expected a number, got a string"},
    {"SampleRateZero", kMain, replace("sample_rate_hz = 100", "sample_rate_hz = 0"),
     "sample_rate_hz", "must be > 0"},
    {"SampleRateTooHigh", kMain, replace("sample_rate_hz = 100", "sample_rate_hz = 10000.5"),
     "sample_rate_hz", "must be in [10, 10000], got 10000.5"},
    {"SampleRateTooLowForTheDetectorsWindows", kMain,
     replace("sample_rate_hz = 100", "sample_rate_hz = 9.5"), "sample_rate_hz",
     "must be in [10, 10000], got 9.5"},
    {"SampleRateNan", kMain, replace("sample_rate_hz = 100", "sample_rate_hz = nan"),
     "sample_rate_hz", "finite"},
    {"WidthZero", kMain, replace("width_mm = 7.5", "width_mm = 0"), "sensor.width_mm",
     "must be > 0"},
    {"HeightNegative", kMain, replace("height_mm = 15.0", "height_mm = -1"), "sensor.height_mm",
     "must be > 0"},
    {"PitchXBelowWidth", kMain, replace("pitch_x_mm = 7.5", "pitch_x_mm = 7.4"),
     "sensor.pitch_x_mm", "must be >= 7.5"},
    {"PitchYBelowHeight", kMain, replace("pitch_y_mm = 15.0", "pitch_y_mm = 14.9"),
     "sensor.pitch_y_mm", "must be >= 15"},
    {"WidthHuge", kMain, replace("width_mm = 7.5", "width_mm = 1e308"), "sensor.width_mm",
     "must be <= 50 mm, got 1e+308"},
    {"HeightAboveACell", kMain, replace("height_mm = 15.0", "height_mm = 50.5"),
     "sensor.height_mm", "must be <= 50 mm, got 50.5"},
    {"PitchXAboveACell", kMain, replace("pitch_x_mm = 7.5", "pitch_x_mm = 51"),
     "sensor.pitch_x_mm", "must be <= 50 mm, got 51"},
    {"PitchYAboveACell", kMain, replace("pitch_y_mm = 15.0", "pitch_y_mm = 1e9"),
     "sensor.pitch_y_mm", "must be <= 50 mm, got 1000000000"},
    {"AlignmentUnknown", kMain, replace("row_alignment = \"centred\"", "row_alignment = \"left\""),
     "sensor.row_alignment", "got \"left\""},
    {"FullScaleBitsZero", kMain, replace("full_scale_bits = 255", "full_scale_bits = 0"),
     "calibration.full_scale_bits", "must be > 0"},
    {"FullScalePressureNegative", kMain,
     replace("full_scale_n_per_cm2 = 64.0", "full_scale_n_per_cm2 = -64.0"),
     "calibration.full_scale_n_per_cm2", "must be > 0"},
    {"CreepGainNegative", kMain, replace("[sensor_creep]", "\ngain = 0\n", "\ngain = -0.1\n"),
     "sensor_creep.gain", "must be in [0, 2], got -0.1"},
    {"CreepGainAboveWhatIsFitted", kMain,
     replace("[sensor_creep]", "\ngain = 0\n", "\ngain = 2.5\n"), "sensor_creep.gain",
     "must be in [0, 2], got 2.5"},
    {"CreepTauZero", kMain, replace("[sensor_creep]", "tau_s = 1.0", "tau_s = 0"),
     "sensor_creep.tau_s", "must be in [0.02, 60], got 0"},
    {"CreepTauNan", kMain, replace("[sensor_creep]", "tau_s = 1.0", "tau_s = nan"),
     "sensor_creep.tau_s", "finite"},
    {"CreepWithoutTau", kMain, replace("[sensor_creep]", "tau_s = 1.0\n", ""),
     "sensor_creep.tau_s", "missing"},
    {"EventThresholdZero", kMain, replace("event_threshold_bits = 142", "event_threshold_bits = 0"),
     "segmentation.event_threshold_bits", "must be in [1, 41055]"},
    {"EventThresholdTooHigh", kMain,
     replace("event_threshold_bits = 142", "event_threshold_bits = 41056"),
     "segmentation.event_threshold_bits", "must be in [1, 41055]"},
    {"DebounceZero", kMain, replace("debounce_frames = 5", "debounce_frames = 0"),
     "segmentation.debounce_frames", "must be in [1, 100]"},
    {"DebounceTooHigh", kMain, replace("debounce_frames = 5", "debounce_frames = 101"),
     "segmentation.debounce_frames", "must be in [1, 100]"},
    {"SwingWindowZero", kMain, replace("swing_window_frames = 5", "swing_window_frames = 0"),
     "segmentation.swing_window_frames", "must be in [1, 100]"},
    {"SwingWindowTooHigh", kMain, replace("swing_window_frames = 5", "swing_window_frames = 101"),
     "segmentation.swing_window_frames", "must be in [1, 100]"},
    {"NoiseSdsNegative", kMain, replace("threshold_noise_sds = 4", "threshold_noise_sds = -0.5"),
     "segmentation.threshold_noise_sds", "must be >= 0, got -0.5"},
    {"NoiseSdsTooHigh", kMain, replace("threshold_noise_sds = 4", "threshold_noise_sds = 20.5"),
     "segmentation.threshold_noise_sds", "must be <= 20, got 20.5"},
    {"MaxGapOneSamplePeriod", kMain, replace("max_gap_s = 0.055", "max_gap_s = 0.01"),
     "segmentation.max_gap_s", "must be > 0.015, got 0.01"},
    {"MaxGapNegative", kMain, replace("max_gap_s = 0.055", "max_gap_s = -1"),
     "segmentation.max_gap_s", "must be > 0.015, got -1"},
    {"MaxGapNotANumber", kMain, replace("max_gap_s = 0.055", "max_gap_s = \"0.05\""),
     "segmentation.max_gap_s", "a number"},
    {"InsolesFileMissing", kMain, replace("\"insoles.toml\"", "\"nope.toml\""), "insoles_file",
     "nope.toml: no such file"},
    {"InsolesFileEmpty", kMain, replace("\"insoles.toml\"", "\"\""), "insoles_file",
     "must name a file"},
    {"TissueFileMissing", kMain, replace("\"tissue_seed_appendix_i.toml\"", "\"nope.toml\""),
     "tissue_file", "nope.toml: no such file"},

    // The insole layouts.
    {"InsolesSyntaxError", kInsoles, prepend("[sizes\n"), "(syntax)", "line 1, column"},
    {"InsolesUnknownTopLevelKey", kInsoles, prepend("version = 2\n"), "version", "unknown key"},
    {"UnknownKeyInSize", kInsoles,
     replace(kSize37, "adaptive_threshold_pct = 0.2\n", "adaptive_threshold_pct = 0.2\nextra = 1\n"),
     "sizes.\"37-38\".extra", "unknown key"},
    {"ThresholdZero", kInsoles,
     replace(kSize37, "adaptive_threshold_pct = 0.2", "adaptive_threshold_pct = 0"),
     "sizes.\"37-38\".adaptive_threshold_pct", "must be > 0"},
    {"ThresholdAbove100", kInsoles,
     replace(kSize37, "adaptive_threshold_pct = 0.2", "adaptive_threshold_pct = 100.5"),
     "sizes.\"37-38\".adaptive_threshold_pct", "must be <= 100"},
    {"ThresholdMissing", kInsoles, replace(kSize37, "adaptive_threshold_pct = 0.2\n", ""),
     "sizes.\"37-38\".adaptive_threshold_pct", "missing"},
    {"MissingSize", kInsoles, truncate_at("[sizes.\"45-46\"]"), "sizes.\"45-46\"", "missing"},
    {"UnknownSize", kInsoles, replace("[sizes.\"45-46\"]", "[sizes.\"47-48\"]"),
     "sizes.\"47-48\"", "unknown name"},
    {"UnknownRegion", kInsoles, replace(kRegions37, "toes3_5           =", "toes3_6 ="),
     "sizes.\"37-38\".regions.toes3_6", "unknown name"},
    {"MissingRegion", kInsoles, replace(kRegions37, "toe2              = [\"1:4\", \"2:5\"]\n", ""),
     "sizes.\"37-38\".regions.toe2", "missing"},
    {"EmptyRegion", kInsoles, replace(kRegions37, "[\"1:4\", \"2:5\"]", "[]"),
     "sizes.\"37-38\".regions.toe2", "lists no sensors"},
    {"RegionNotAnArray", kInsoles, replace(kRegions37, "[\"1:5\", \"2:6-7\"]", "\"1:5\""),
     "sizes.\"37-38\".regions.toe1", "expected an array"},
    {"SpanNotAString", kInsoles, replace(kRegions37, "\"1:5\"", "5"),
     "sizes.\"37-38\".regions.toe1[0]", "expected a string"},
    {"MalformedSpan", kInsoles, replace(kRegions37, "\"1:5\"", "\"1-5\""),
     "sizes.\"37-38\".regions.toe1[0]", "malformed span \"1-5\""},
    {"MalformedSpanTrailingDash", kInsoles, replace(kRegions37, "\"2:6-7\"", "\"2:6-\""),
     "sizes.\"37-38\".regions.toe1[1]", "malformed span \"2:6-\""},
    {"MalformedSpanNegative", kInsoles, replace(kRegions37, "\"2:6-7\"", "\"-2:6-7\""),
     "sizes.\"37-38\".regions.toe1[1]", "malformed span"},
    {"RowZero", kInsoles, replace(kRegions37, "\"1:5\"", "\"0:5\""),
     "sizes.\"37-38\".regions.toe1[0]", "row must be >= 1, got 0"},
    {"FirstSensorZero", kInsoles, replace(kRegions37, "\"2:6-7\"", "\"2:0-7\""),
     "sizes.\"37-38\".regions.toe1[1]", "first sensor must be >= 1, got 0"},
    {"FirstAfterLast", kInsoles, replace(kRegions37, "\"2:6-7\"", "\"2:7-6\""),
     "sizes.\"37-38\".regions.toe1[1]", "first sensor 7 is after last sensor 6"},
    {"SensorNumberHuge", kInsoles, replace(kRegions37, "\"2:6-7\"", "\"2:6-99999999999\""),
     "sizes.\"37-38\".regions.toe1[1]", "must be <= 100"},
    // toe1 (read before toe2) already holds row 1 sensor 5.
    {"SensorInTwoRegions", kInsoles, replace(kRegions37, "\"1:4\"", "\"1:4-5\""),
     "sizes.\"37-38\".regions.toe2[0]", "row 1 sensor 5 is in both toe1 and toe2"},
    {"SensorListedTwice", kInsoles,
     replace(kRegions37, "[\"1:5\", \"2:6-7\"]", "[\"1:5\", \"2:6-7\", \"1:5\"]"),
     "sizes.\"37-38\".regions.toe1[2]", "row 1 sensor 5 is listed twice in toe1"},
    {"SensorInNoRegion", kInsoles, replace(kRegions37, "\"2:6-7\"", "\"2:7\""),
     "sizes.\"37-38\".regions", "row 2 sensor 6 is in no region"},
    // Row 15 one sensor short: 106 sensors where size 37-38 has 107 (and one more: 108).
    {"SensorCountOfAnotherSize", kInsoles, replace("\"15:1-4\"", "\"15:1-3\""),
     "sizes.\"37-38\".regions", "the regions hold 106 sensors; insole size 37-38 has 107"},
    {"SensorCountOneTooMany", kInsoles, replace("\"15:1-4\"", "\"15:1-5\""),
     "sizes.\"37-38\".regions", "the regions hold 108 sensors; insole size 37-38 has 107"},
    {"EmptyRowBetweenRows", kInsoles,
     replace(kRegions37, "[\"8:1-7\", \"9:1-7\"]", "[\"8:1-7\"]"), "sizes.\"37-38\".regions",
     "row 9 has no sensors"},

    // The seed's tissue parameters.
    {"TissueSyntaxError", kTissue, prepend("x =\n"), "(syntax)", "line 1, column"},
    {"TissueMissingSize", kTissue, truncate_at("[sizes.\"45-46\".heel]"), "sizes.\"45-46\"",
     "missing"},
    {"TissueUnknownSize", kTissue, replace("[sizes.\"35-36\".heel]", "[sizes.\"34-35\".heel]"),
     "sizes.\"34-35\"", "unknown name"},
    {"TissueMissingRegion", kTissue, truncate_at("[sizes.\"45-46\".toes3_5]"),
     "sizes.\"45-46\".toes3_5", "missing"},
    {"TissueUnknownRegion", kTissue, replace("[sizes.\"37-38\".toe2]", "[sizes.\"37-38\".toe_2]"),
     "sizes.\"37-38\".toe_2", "unknown name"},
    {"TissueMissingParam", kTissue,
     replace(kHeel37, "nrmse_pct       = { mean = 25.5, sd = 4.2 }\n", ""),
     "sizes.\"37-38\".heel.nrmse_pct", "missing"},
    {"TissueUnknownParam", kTissue,
     replace(kHeel37, "[sizes.\"37-38\".heel]\n", "[sizes.\"37-38\".heel]\nq = { mean = 1.0, sd = 0.1 }\n"),
     "sizes.\"37-38\".heel.q", "unknown key"},
    {"TissueParamNotATable", kTissue, replace(kHeel37, "{ mean = 16.4, sd = 0.9 }", "16.4"),
     "sizes.\"37-38\".heel.d0_mm", "expected a table, got a floating-point number"},
    {"TissueMissingSd", kTissue, replace(kHeel37, "{ mean = 16.4, sd = 0.9 }", "{ mean = 16.4 }"),
     "sizes.\"37-38\".heel.d0_mm.sd", "missing"},
    {"TissueUnknownStatKey", kTissue,
     replace(kHeel37, "{ mean = 16.4, sd = 0.9 }", "{ mean = 16.4, sd = 0.9, median = 16.0 }"),
     "sizes.\"37-38\".heel.d0_mm.median", "unknown key"},
    {"TissueMeanZero", kTissue,
     replace(kHeel37, "{ mean = 0.117, sd = 0.027 }", "{ mean = 0.0, sd = 0.027 }"),
     "sizes.\"37-38\".heel.kbar_n_per_mm3.mean", "must be > 0"},
    {"TissueSdNegative", kTissue,
     replace(kHeel37, "{ mean = 0.117, sd = 0.027 }", "{ mean = 0.117, sd = -0.027 }"),
     "sizes.\"37-38\".heel.kbar_n_per_mm3.sd", "must be >= 0"},
};
// clang-format on

INSTANTIATE_TEST_SUITE_P(Rules, ConfigRefusal, ::testing::ValuesIn(kRefusals),
                         [](const ::testing::TestParamInfo<Refusal>& info) {
                           return info.param.name;
                         });

// The [fit] bounds: min(mean - 3 SD) and max(mean + 3 SD) of Appendix I over all sizes and
// regions, worked out by hand from seed-data/seed_table_I_results.csv (floors where negative).
TEST(Config, FitBoundsAreDerivedFromAppendixI) {
  const FitBounds b = load_config(shipped_config_path()).fit_bounds;
  EXPECT_DOUBLE_EQ(b.A_mm.lower, 20.0);              // toe1 35-36: 39.2 - 3 x 6.0
  EXPECT_DOUBLE_EQ(b.A_mm.upper, 213.5);             // heel 43-44: 140.6 + 3 x 24.3
  EXPECT_DOUBLE_EQ(b.B_mm.lower, 10.2);              // toe2 35-36: 16.2 - 3 x 2.0
  EXPECT_DOUBLE_EQ(b.B_mm.upper, 219.7);             // heel 43-44: 142.3 + 3 x 25.8
  EXPECT_DOUBLE_EQ(b.C_mm.lower, 15.6);              // midfoot_anterior 35-36: 31.8 - 3 x 5.4
  EXPECT_DOUBLE_EQ(b.C_mm.upper, 186.1);             // met3_5 43-44: 145.0 + 3 x 13.7
  EXPECT_DOUBLE_EQ(b.d0_mm.lower, 1.0);              // floor (toe1 45-46: 3.5 - 3 x 2.1 < 0)
  EXPECT_DOUBLE_EQ(b.d0_mm.upper, 22.8);             // heel 39-40: 19.3 + 3 x 1.1
  EXPECT_DOUBLE_EQ(b.kbar_n_per_mm3.lower, 0.017);   // heel 37-38: 0.117 - 3 x 0.027
  EXPECT_DOUBLE_EQ(b.kbar_n_per_mm3.upper, 0.354);   // heel 43-44: 0.186 + 3 x 0.056
  EXPECT_DOUBLE_EQ(b.n.lower, 0.01);                 // floor
  EXPECT_DOUBLE_EQ(b.n.upper, 0.981);                // met1_2 35-36: 0.567 + 3 x 0.138
  EXPECT_DOUBLE_EQ(b.cbar_ns_per_mm3.lower, 0.001);  // floor
  EXPECT_DOUBLE_EQ(b.cbar_ns_per_mm3.upper, 0.052);  // midfoot_posterior 43-44: 0.022 + 0.030
  EXPECT_DOUBLE_EQ(b.m.lower, 0.82);                 // midfoot_posterior 45-46: 1.09 - 3 x 0.09
  EXPECT_DOUBLE_EQ(b.m.upper, 1.38);                 // midfoot_posterior 43-44: 1.14 + 3 x 0.08
}

TEST(Config, FitBoundsAreValidated) {
  const std::vector<Refusal> cases = {
      {"FitUnknownKey", kMain, replace("[fit]\n", "[fit]\nP_mm2 = { lower = 1.0, upper = 2.0 }\n"),
       "fit.P_mm2", "unknown key"},
      {"FitMissing", kMain, replace("m = { lower = 0.82, upper = 1.38 }\n", ""), "fit.m",
       "missing"},
      {"FitLowerZero", kMain,
       replace("{ lower = 0.01, upper = 0.981 }", "{ lower = 0.0, upper = 0.981 }"), "fit.n.lower",
       "must be > 0"},
      {"FitUpperBelowLower", kMain,
       replace("{ lower = 20.0, upper = 213.5 }", "{ lower = 20.0, upper = 19.0 }"),
       "fit.A_mm.upper", "must be > lower"},
      {"FitUnknownBoundKey", kMain,
       replace("{ lower = 1.0, upper = 22.8 }", "{ lower = 1.0, upper = 22.8, mid = 5.0 }"),
       "fit.d0_mm.mid", "unknown key"},
  };
  expect_refusals(cases);
}

TEST(Config, WireAndSerialDefaults) {
  const Config config = load_config(shipped_config_path());
  EXPECT_EQ(config.wire.sync, (std::vector<std::uint8_t>{0xA5, 0x5A}));
  EXPECT_EQ(config.wire.crc, CrcKind::Crc16CcittFalse);
  EXPECT_FALSE(config.wire.crc_big_endian);
  EXPECT_TRUE(config.wire.require_size_sensor_count);
  EXPECT_EQ(config.serial.device, "/dev/ttyUSB0");
  EXPECT_EQ(config.serial.baud, 921600U);
  EXPECT_EQ(config.serial.parity, SerialParity::None);
  EXPECT_EQ(config.serial.data_bits, 8);
  EXPECT_EQ(config.serial.stop_bits, 1);
  EXPECT_EQ(config.serial.flow_control, SerialFlowControl::None);
  EXPECT_EQ(config.serial.reconnect_initial_ms, 50);
  EXPECT_EQ(config.serial.reconnect_max_ms, 2000);
  EXPECT_EQ(config.usb.vendor_id, 0);
  EXPECT_EQ(config.usb.product_id, 0);
  EXPECT_EQ(config.usb.interface, 0);
  EXPECT_EQ(config.usb.endpoint, 0x81);
  EXPECT_EQ(config.usb.transfers, 4);
  EXPECT_EQ(config.usb.transfer_bytes, 16384);
  EXPECT_EQ(config.usb.reconnect_initial_ms, 50);
  EXPECT_EQ(config.usb.reconnect_max_ms, 2000);
}

TEST(Config, WireAndSerialAcceptTheirAlternatives) {
  const fs::path dir = copy_config("WireAlternatives");
  edit_file(dir / kMain, [](std::string& text) {
    replace("sync = [0xA5, 0x5A]", "sync = [0x7E]")(text);
    replace("crc = \"crc16-ccitt-false\"", "crc = \"crc32\"")(text);
    replace("crc_byte_order = \"little\"", "crc_byte_order = \"big\"")(text);
    replace("require_size_sensor_count = true", "require_size_sensor_count = false")(text);
    replace("parity = \"none\"", "parity = \"even\"")(text);
    replace("flow_control = \"none\"", "flow_control = \"hardware\"")(text);
  });
  const Config config = load_config(dir / kMain);
  EXPECT_EQ(config.wire.sync, (std::vector<std::uint8_t>{0x7E}));
  EXPECT_EQ(config.wire.crc, CrcKind::Crc32);
  EXPECT_TRUE(config.wire.crc_big_endian);
  EXPECT_FALSE(config.wire.require_size_sensor_count);
  EXPECT_EQ(config.serial.parity, SerialParity::Even);
  EXPECT_EQ(config.serial.flow_control, SerialFlowControl::Hardware);
}

TEST(Config, WireAndSerialAreValidated) {
  const std::vector<Refusal> cases = {
      {"WireMissing", kMain, erase_from_to("[wire]\n", "[serial]\n"), "wire", "missing"},
      {"WireUnknownKey", kMain, replace("[wire]\n", "[wire]\nsink = 1\n"), "wire.sink",
       "unknown key"},
      {"WireSyncEmpty", kMain, replace("sync = [0xA5, 0x5A]", "sync = []"), "wire.sync",
       "must list 1 to 4 bytes, got 0"},
      {"WireSyncTooLong", kMain, replace("sync = [0xA5, 0x5A]", "sync = [1, 2, 3, 4, 5]"),
       "wire.sync", "must list 1 to 4 bytes, got 5"},
      {"WireSyncByteTooLarge", kMain, replace("sync = [0xA5, 0x5A]", "sync = [0xA5, 256]"),
       "wire.sync[1]", "must be in [0, 255], got 256"},
      {"WireSyncByteNotInteger", kMain, replace("sync = [0xA5, 0x5A]", "sync = [\"A5\"]"),
       "wire.sync[0]", "expected an integer, got a string"},
      {"WireUnknownCrc", kMain, replace("crc = \"crc16-ccitt-false\"", "crc = \"crc8\""),
       "wire.crc", "must be one of \"crc16-ccitt-false\", \"crc32\", \"none\", got \"crc8\""},
      {"WireBadByteOrder", kMain,
       replace("crc_byte_order = \"little\"", "crc_byte_order = \"middle\""), "wire.crc_byte_order",
       "must be one of"},
      {"WireCountNotBoolean", kMain,
       replace("require_size_sensor_count = true", "require_size_sensor_count = 1"),
       "wire.require_size_sensor_count", "expected a boolean, got an integer"},
      {"SerialMissing", kMain, erase_from_to("[serial]\n", "[usb]\n"), "serial", "missing"},
      {"SerialUnknownKey", kMain, replace("[serial]\n", "[serial]\nbaudrate = 9600\n"),
       "serial.baudrate", "unknown key"},
      {"SerialEmptyDevice", kMain, replace("device = \"/dev/ttyUSB0\"", "device = \"\""),
       "serial.device", "must not be empty"},
      {"SerialBaudZero", kMain, replace("baud = 921600", "baud = 0"), "serial.baud",
       "must be in [50, 4000000], got 0"},
      {"SerialBadParity", kMain, replace("parity = \"none\"", "parity = \"mark\""), "serial.parity",
       "must be one of \"none\", \"odd\", \"even\", got \"mark\""},
      {"SerialDataBits", kMain, replace("data_bits = 8", "data_bits = 9"), "serial.data_bits",
       "must be in [5, 8], got 9"},
      {"SerialStopBits", kMain, replace("stop_bits = 1", "stop_bits = 3"), "serial.stop_bits",
       "must be in [1, 2], got 3"},
      {"SerialBadFlow", kMain, replace("flow_control = \"none\"", "flow_control = \"xon\""),
       "serial.flow_control", "must be one of"},
      {"SerialBackoffZero", kMain, replace("reconnect_initial_ms = 50", "reconnect_initial_ms = 0"),
       "serial.reconnect_initial_ms", "must be in [1, 60000], got 0"},
      {"SerialBackoffMaxBelowInitial", kMain,
       replace("reconnect_max_ms = 2000", "reconnect_max_ms = 10"), "serial.reconnect_max_ms",
       "must be >= reconnect_initial_ms (50), got 10"},
      {"UsbMissing", kMain, truncate_at("[usb]\n"), "usb", "missing"},
      {"UsbUnknownKey", kMain, replace("[usb]\n", "[usb]\nserial_number = 1\n"),
       "usb.serial_number", "unknown key"},
      {"UsbVendorTooLarge", kMain, replace("vendor_id = 0x0000", "vendor_id = 0x10000"),
       "usb.vendor_id", "must be in [0, 65535], got 65536"},
      {"UsbOutEndpoint", kMain, replace("endpoint = 0x81", "endpoint = 0x01"), "usb.endpoint",
       "must be an IN endpoint address 0x81-0x8F, got 0x01"},
      {"UsbTransfersZero", kMain, replace("transfers = 4", "transfers = 0"), "usb.transfers",
       "must be in [1, 64], got 0"},
      {"UsbTransferBytes", kMain, replace("transfer_bytes = 16384", "transfer_bytes = 8"),
       "usb.transfer_bytes", "must be in [64, 1048576], got 8"},
      {"UsbBackoffMaxBelowInitial", kMain,
       replace("[usb]", "reconnect_max_ms = 2000", "reconnect_max_ms = 1"), "usb.reconnect_max_ms",
       "must be >= reconnect_initial_ms (50), got 1"},
  };
  expect_refusals(cases);
}

TEST(Config, RingAndMonitorHaveTheDocumentedDefaults) {
  const Config config = load_config(shipped_config_path());
  EXPECT_EQ(config.ring.capacity_frames, 4096u);
  EXPECT_EQ(config.monitor.workers, 2);
  EXPECT_EQ(config.monitor.max_step_backlog, 32);
  EXPECT_DOUBLE_EQ(config.monitor.status_period_s, 1.0);
  EXPECT_TRUE(config.monitor.publish_frames);
  EXPECT_EQ(config.monitor.tissue_window_steps, 400);
  EXPECT_EQ(MonitorSettings{}.tissue_window_steps, 400);
}

TEST(Config, RingAndMonitorAreValidated) {
  const std::vector<Refusal> cases = {
      {"RingMissing", kMain, erase_from_to("[ring]", "[monitor]"), "ring", "missing"},
      {"RingCapacityOne", kMain, replace("capacity_frames = 4096", "capacity_frames = 1"),
       "ring.capacity_frames", "must be in [2, 16777216]"},
      {"RingCapacityFloat", kMain, replace("capacity_frames = 4096", "capacity_frames = 4096.0"),
       "ring.capacity_frames", "expected an integer"},
      {"RingUnknownKey", kMain, replace("[ring]\n", "[ring]\npolicy = \"drop\"\n"), "ring.policy",
       "unknown key"},
      {"MonitorWorkersZero", kMain, replace("workers = 2", "workers = 0"), "monitor.workers",
       "must be in [1, 64]"},
      {"MonitorBacklogZero", kMain, replace("max_step_backlog = 32", "max_step_backlog = 0"),
       "monitor.max_step_backlog", "must be in [1, 100000]"},
      {"MonitorStatusPeriodZero", kMain, replace("status_period_s = 1.0", "status_period_s = 0"),
       "monitor.status_period_s", "must be in [0.01, 3600]"},
      {"MonitorPublishFramesNotBool", kMain, replace("publish_frames = true", "publish_frames = 1"),
       "monitor.publish_frames", "expected a boolean"},
      {"MonitorPublishFramesMissing", kMain, replace("publish_frames = true\n", ""),
       "monitor.publish_frames", "missing"},
      {"MonitorUnknownKey", kMain, replace("[monitor]\n", "[monitor]\nthreads = 2\n"),
       "monitor.threads", "unknown key"},
      {"MonitorTissueWindowBelowAPool", kMain,
       replace("tissue_window_steps = 400", "tissue_window_steps = 2"),
       "monitor.tissue_window_steps", "must be in [3, 100000], got 2"},
      {"MonitorTissueWindowMissing", kMain, replace("tissue_window_steps = 400\n", ""),
       "monitor.tissue_window_steps", "missing"},
  };
  expect_refusals(cases);
  const fs::path dir = copy_config("MonitorTissueWindow");
  edit_file(dir / kMain, replace("tissue_window_steps = 400", "tissue_window_steps = 3"));
  EXPECT_EQ(load_config(dir / kMain).monitor.tissue_window_steps, 3);
}

TEST(Config, LcmDefaultsWorkOnOneMachineWithoutNetwork) {
  const LcmSettings lcm = load_config(shipped_config_path()).lcm;
  EXPECT_EQ(lcm.url, "udpm://239.255.76.67:7667?ttl=0");
  EXPECT_FALSE(lcm.raw_enabled);
  EXPECT_EQ(lcm.channels.frame, "GAITMON_FRAME");
  EXPECT_EQ(lcm.channels.step, "GAITMON_STEP");
  EXPECT_EQ(lcm.channels.fit, "GAITMON_FIT");
  EXPECT_EQ(lcm.channels.status, "GAITMON_STATUS");
  EXPECT_EQ(lcm.channels.raw, "GAITMON_RAW");
  EXPECT_EQ(lcm.channels.effects, "GAITMON_EFFECTS");
  EXPECT_EQ(lcm.channels.tissue, "GAITMON_TISSUE");
  // The struct's defaults are the shipped file's, for code that builds settings by hand.
  const LcmSettings defaults;
  EXPECT_EQ(defaults.url, lcm.url);
  EXPECT_EQ(defaults.channels.fit, lcm.channels.fit);
}

TEST(Config, LcmSettingsAreRead) {
  const fs::path dir = copy_config("LcmRead");
  edit_file(dir / kMain, replace("[lcm]", "raw_enabled = false", "raw_enabled = true"));
  edit_file(dir / kMain, replace("[lcm]", "?ttl=0\"", "?ttl=1\""));
  edit_file(dir / kMain, replace("[lcm.channels]", "\"GAITMON_FIT\"", "\"LAB2.FIT\""));
  const LcmSettings lcm = load_config(dir / kMain).lcm;
  EXPECT_TRUE(lcm.raw_enabled);
  EXPECT_EQ(lcm.url, "udpm://239.255.76.67:7667?ttl=1");
  EXPECT_EQ(lcm.channels.fit, "LAB2.FIT");
  EXPECT_EQ(lcm.channels.step, "GAITMON_STEP");
}

TEST(Config, LcmSettingsAreValidated) {
  const std::string too_long(64, 'C');
  const std::vector<Refusal> cases = {
      {"LcmMissingTable", kMain, truncate_at("[lcm]\n"), "lcm", "missing"},
      {"LcmMissingUrl", kMain, replace("[lcm]", "url = \"udpm://239.255.76.67:7667?ttl=0\"\n", ""),
       "lcm.url", "missing"},
      {"LcmUnknownKey", kMain, replace("[lcm]\n", "[lcm]\nttl = 0\n"), "lcm.ttl", "unknown key"},
      {"LcmUrlNoProvider", kMain,
       replace("[lcm]", "\"udpm://239.255.76.67:7667?ttl=0\"", "\"239.255.76.67\""), "lcm.url",
       "is not PROVIDER://"},
      {"LcmUrlUnknownProvider", kMain, replace("[lcm]", "\"udpm://", "\"udp://"), "lcm.url",
       "providers are udpm"},
      {"LcmUrlNotString", kMain, replace("[lcm]", "\"udpm://239.255.76.67:7667?ttl=0\"", "7667"),
       "lcm.url", "expected a string, got an integer"},
      {"LcmRawNotBoolean", kMain, replace("[lcm]", "raw_enabled = false", "raw_enabled = \"no\""),
       "lcm.raw_enabled", "expected a boolean, got a string"},
      {"LcmChannelMissing", kMain, replace("[lcm.channels]", "status = \"GAITMON_STATUS\"", ""),
       "lcm.channels.status", "missing"},
      {"LcmChannelUnknown", kMain, replace("[lcm.channels]\n", "[lcm.channels]\nevents = \"E\"\n"),
       "lcm.channels.events", "unknown key"},
      {"LcmChannelEmpty", kMain, replace("[lcm.channels]", "\"GAITMON_STEP\"", "\"\""),
       "lcm.channels.step", "must name a channel"},
      {"LcmChannelSpace", kMain, replace("[lcm.channels]", "\"GAITMON_STEP\"", "\"GAITMON STEP\""),
       "lcm.channels.step", "space or a control character"},
      {"LcmChannelTooLong", kMain,
       replace("[lcm.channels]", "\"GAITMON_RAW\"", "\"" + too_long + "\""), "lcm.channels.raw",
       "at most 63 characters, got 64"},
      {"LcmChannelTwice", kMain, replace("[lcm.channels]", "\"GAITMON_STATUS\"", "\"GAITMON_FIT\""),
       "lcm.channels.status", "is also the fit channel"},
      {"LcmEffectsChannelMissing", kMain,
       replace("[lcm.channels]", "effects = \"GAITMON_EFFECTS\"", ""), "lcm.channels.effects",
       "missing"},
      {"LcmEffectsChannelTwice", kMain,
       replace("[lcm.channels]", "\"GAITMON_EFFECTS\"", "\"GAITMON_STEP\""), "lcm.channels.effects",
       "is also the step channel"},
      {"LcmTissueChannelMissing", kMain,
       replace("[lcm.channels]", "tissue = \"GAITMON_TISSUE\"", ""), "lcm.channels.tissue",
       "missing"},
      {"LcmTissueChannelTwice", kMain,
       replace("[lcm.channels]", "\"GAITMON_TISSUE\"", "\"GAITMON_EFFECTS\""),
       "lcm.channels.tissue", "is also the effects channel"},
  };
  expect_refusals(cases);
}

}  // namespace
}  // namespace gaitmon

namespace gaitmon {
namespace {

TEST(Config, ModelEffectsDefaultToNoneAndAreValidated) {
  EXPECT_TRUE(load_config(shipped_config_path()).model.effects.empty());
  EXPECT_EQ(load_config(shipped_config_path()).model.effects_window_steps, 100);
  EXPECT_EQ(ModelSettings{}.effects_window_steps, 100);
  const std::vector<Refusal> cases = {
      {"ModelUnknownEffect", kMain, replace("effects = []", R"(effects = ["ghosting"])"),
       "model.effects[0]", "unknown effect 'ghosting'"},
      {"ModelEffectTwice", kMain,
       replace("effects = []", R"(effects = ["hysteresis", "hysteresis"])"), "model.effects[1]",
       "listed twice"},
      {"ModelEffectNotString", kMain, replace("effects = []", "effects = [1]"), "model.effects[0]",
       "must be a string"},
      {"ModelUnknownKey", kMain, replace("effects = []", "effects = []\nstrength = 1"),
       "model.strength", "unknown key"},
      {"ModelMissing", kMain, replace("effects = []", ""), "model.effects", "missing"},
      {"ModelWindowBelowTheFolds", kMain,
       replace("effects_window_steps = 100", "effects_window_steps = 4"),
       "model.effects_window_steps", "must be in [5, 100000], got 4"},
      {"ModelWindowNotInteger", kMain,
       replace("effects_window_steps = 100", "effects_window_steps = 100.5"),
       "model.effects_window_steps", "expected an integer"},
      {"ModelWindowMissing", kMain, replace("effects_window_steps = 100\n", ""),
       "model.effects_window_steps", "missing"},
  };
  expect_refusals(cases);
  const fs::path dir = copy_config("ModelTwoEffects");
  edit_file(dir / kMain,
            replace("effects = []", R"(effects = ["sensor_saturation", "impact_transient"])"));
  edit_file(dir / kMain, replace("effects_window_steps = 100", "effects_window_steps = 40"));
  EXPECT_EQ(load_config(dir / kMain).model.effects,
            (std::vector<std::string>{"sensor_saturation", "impact_transient"}));
  EXPECT_EQ(load_config(dir / kMain).model.effects_window_steps, 40);
}

// [model] m_per_session: off by default; on, analyze and the live monitor take one m per region
// over the steps (the monitor over its window), which the effects' fits cannot share.
TEST(Config, ModelRunningMIsOffByDefaultAndValidated) {
  const ModelSettings shipped = load_config(shipped_config_path()).model;
  EXPECT_FALSE(shipped.m_per_session);
  EXPECT_EQ(shipped.m_window_steps, 200);
  EXPECT_FALSE(ModelSettings{}.m_per_session);
  EXPECT_EQ(ModelSettings{}.m_window_steps, 200);
  const std::vector<Refusal> cases = {
      {"ModelRunningMNotBoolean", kMain, replace("m_per_session = false", "m_per_session = 1"),
       "model.m_per_session", "expected a boolean"},
      {"ModelRunningMMissing", kMain, replace("m_per_session = false\n", ""), "model.m_per_session",
       "missing"},
      {"ModelRunningMWithEffects", kMain,
       [](std::string& text) {
         replace("m_per_session = false", "m_per_session = true")(text);
         replace("effects = []", R"(effects = ["hysteresis"])")(text);
       },
       "model.m_per_session", "cannot be true with [model] effects"},
      {"ModelRunningMWindowBelowTheFirstEstimate", kMain,
       replace("m_window_steps = 200", "m_window_steps = 9"), "model.m_window_steps",
       "must be in [10, 100000], got 9"},
      {"ModelRunningMWindowMissing", kMain, replace("m_window_steps = 200\n", ""),
       "model.m_window_steps", "missing"},
  };
  expect_refusals(cases);
  const fs::path dir = copy_config("ModelRunningM");
  edit_file(dir / kMain, replace("m_per_session = false", "m_per_session = true"));
  edit_file(dir / kMain, replace("m_window_steps = 200", "m_window_steps = 50"));
  EXPECT_TRUE(load_config(dir / kMain).model.m_per_session);
  EXPECT_EQ(load_config(dir / kMain).model.m_window_steps, 50);
}

// [model] area: auto as shipped (analyze takes the footprint the session's cells call for, the
// live monitor the footprint); else one of analyze's areas, and nothing else.
TEST(Config, ModelAreaIsAutoAsShippedAndValidated) {
  EXPECT_EQ(load_config(shipped_config_path()).model.area, "auto");
  EXPECT_EQ(ModelSettings{}.area, "auto");
  const std::vector<Refusal> cases = {
      {"ModelAreaUnknown", kMain, replace(R"(area = "auto")", R"(area = "cells")"), "model.area",
       R"(must be "auto", "footprint", "footprint-mean" or "ellipse", got "cells")"},
      {"ModelAreaNotAString", kMain, replace(R"(area = "auto")", "area = 1"), "model.area",
       "expected a string"},
      {"ModelAreaMissing", kMain, replace("area = \"auto\"\n", ""), "model.area", "missing"},
  };
  expect_refusals(cases);
  const fs::path dir = copy_config("ModelArea");
  edit_file(dir / kMain, replace(R"(area = "auto")", R"(area = "footprint-mean")"));
  EXPECT_EQ(load_config(dir / kMain).model.area, "footprint-mean");
}

// [asymmetry] and [asymmetry.m_per_session], and the same two of [asymmetry.footprint_mean]:
// every region's SD for kbar and cbar, as the shipped file documents them; each must be there,
// known and in [0, 100].
TEST(Config, AsymmetryPairSdsAreReadPerRegionAndValidated) {
  const AsymmetrySettings a = load_config(shipped_config_path()).asymmetry;
  using PerRegion = std::array<double, kRegionCount>;
  EXPECT_EQ(a.per_step.kbar_pair_sd_pct, (PerRegion{1.0, 4.5, 4.5, 2.5, 2.0, 1.0, 1.0, 3.0}));
  EXPECT_EQ(a.per_step.cbar_pair_sd_pct, (PerRegion{3.0, 6.0, 4.5, 5.5, 5.5, 9.5, 9.5, 12.5}));
  EXPECT_EQ(a.m_per_session.kbar_pair_sd_pct, (PerRegion{1.0, 4.5, 4.5, 2.0, 2.0, 0.5, 1.0, 3.0}));
  EXPECT_EQ(a.m_per_session.cbar_pair_sd_pct, (PerRegion{0.5, 1.5, 1.0, 1.0, 1.0, 3.5, 3.5, 3.5}));
  const AsymmetrySettings mean = load_config(shipped_config_path()).asymmetry_footprint_mean;
  EXPECT_EQ(mean.per_step.kbar_pair_sd_pct, (PerRegion{1.0, 7.0, 6.0, 2.0, 2.5, 9.0, 1.5, 5.0}));
  EXPECT_EQ(mean.per_step.cbar_pair_sd_pct, (PerRegion{1.5, 10.5, 4.0, 4.0, 5.0, 5.5, 5.5, 15.5}));
  EXPECT_EQ(mean.m_per_session.kbar_pair_sd_pct,
            (PerRegion{1.0, 7.0, 6.0, 2.0, 2.0, 2.0, 3.0, 5.0}));
  EXPECT_EQ(mean.m_per_session.cbar_pair_sd_pct,
            (PerRegion{0.5, 3.0, 3.5, 1.0, 1.0, 5.5, 5.5, 8.5}));
  const std::vector<Refusal> cases = {
      {"AsymmetryNegative", kMain,
       replace("kbar_pair_sd_pct = { heel = 1.0", "kbar_pair_sd_pct = { heel = -1"),
       "asymmetry.kbar_pair_sd_pct.heel", "must be in [0, 100], got -1"},
      {"AsymmetryRegionMissing", kMain, replace("cbar_pair_sd_pct", "toe2 = 9.5, ", ""),
       "asymmetry.cbar_pair_sd_pct.toe2", "missing"},
      {"AsymmetryUnknownRegion", kMain,
       replace("cbar_pair_sd_pct", "toe2 = 9.5", "toe2 = 9.5, toe6 = 1"),
       "asymmetry.cbar_pair_sd_pct.toe6", "unknown name"},
      {"AsymmetryNotANumber", kMain,
       replace("kbar_pair_sd_pct", "met3_5 = 2.0", "met3_5 = \"2.0\""),
       "asymmetry.kbar_pair_sd_pct.met3_5", "expected a number"},
      {"AsymmetryMissing", kMain, erase_from_to("[asymmetry]", "[pooling]"), "asymmetry",
       "missing"},
      {"AsymmetrySharedMMissing", kMain, erase_from_to("[asymmetry.m_per_session]", "[pooling]"),
       "asymmetry.m_per_session", "missing"},
      {"AsymmetryFootprintMeanMissing", kMain,
       erase_from_to("[asymmetry.footprint_mean]", "[pooling]"), "asymmetry.footprint_mean",
       "missing"},
      {"AsymmetryFootprintMeanSharedMTooLarge", kMain,
       set_heel("[asymmetry.footprint_mean.m_per_session]", "cbar_pair_sd_pct", "101"),
       "asymmetry.footprint_mean.m_per_session.cbar_pair_sd_pct.heel",
       "must be in [0, 100], got 101"},
  };
  expect_refusals(cases);
  const fs::path dir = copy_config("AsymmetryTrusted");
  edit_file(dir / kMain,
            replace("kbar_pair_sd_pct = { heel = 1.0", "kbar_pair_sd_pct = { heel = 0"));
  EXPECT_EQ(load_config(dir / kMain).asymmetry.per_step.kbar_pair_sd_pct[0], 0.0);
}

// [pooling] and [pooling.m_per_session], and the same two of [pooling.footprint_mean]: every
// region's chain SD and step SD for kbar, n, cbar and m, as the shipped file documents them;
// kbar's and cbar's in [0, 1000] (per cent), n's and m's in [0, 1].
TEST(Config, PoolingChainSdsAreReadPerRegionAndValidated) {
  const PoolingSettings p = load_config(shipped_config_path()).pooling;
  using PerRegion = std::array<double, kRegionCount>;
  EXPECT_EQ(p.per_step.kbar_chain_sd_pct, (PerRegion{4.0, 6.5, 6.5, 5.5, 4.5, 10.5, 102.5, 18.5}));
  EXPECT_EQ(p.per_step.n_chain_sd, (PerRegion{0.02, 0.025, 0.025, 0.04, 0.03, 0.065, 0.0, 0.075}));
  EXPECT_EQ(p.per_step.cbar_chain_sd_pct,
            (PerRegion{13.0, 21.0, 21.5, 12.0, 12.0, 25.0, 227.0, 29.5}));
  EXPECT_EQ(p.per_step.m_chain_sd, (PerRegion{0.06, 0.085, 0.075, 0.07, 0.07, 0.165, 0.24, 0.155}));
  EXPECT_EQ(p.m_per_session.kbar_chain_sd_pct,
            (PerRegion{4.0, 6.5, 6.5, 6.0, 4.5, 9.0, 93.5, 17.5}));
  EXPECT_EQ(p.m_per_session.n_chain_sd,
            (PerRegion{0.02, 0.025, 0.025, 0.04, 0.03, 0.055, 0.0, 0.075}));
  EXPECT_EQ(p.m_per_session.cbar_chain_sd_pct,
            (PerRegion{3.0, 14.5, 17.5, 0.0, 2.5, 0.0, 227.5, 17.5}));
  EXPECT_EQ(p.m_per_session.m_chain_sd,
            (PerRegion{0.06, 0.1, 0.145, 0.145, 0.16, 0.0, 0.215, 0.08}));
  EXPECT_EQ(p.per_step.kbar_step_sd_pct, (PerRegion{0.0, 0.0, 0.0, 10.5, 7.5, 17.0, 0.0, 0.0}));
  EXPECT_EQ(p.per_step.n_step_sd, (PerRegion{0.0, 0.0, 0.0, 0.07, 0.045, 0.0, 0.0, 0.0}));
  EXPECT_EQ(p.per_step.cbar_step_sd_pct, (PerRegion{0.0, 0.0, 0.0, 18.5, 25.0, 111.5, 0.0, 0.0}));
  EXPECT_EQ(p.per_step.m_step_sd, (PerRegion{0.0, 0.0, 0.0, 0.145, 0.16, 0.0, 0.0, 0.0}));
  EXPECT_EQ(p.m_per_session.kbar_step_sd_pct, (PerRegion{0.0, 0.0, 0.0, 9.5, 6.0, 18.0, 0.0, 0.0}));
  EXPECT_EQ(p.m_per_session.n_step_sd, (PerRegion{0.0, 0.0, 0.0, 0.065, 0.035, 0.0, 0.0, 0.0}));
  EXPECT_EQ(p.m_per_session.cbar_step_sd_pct,
            (PerRegion{0.0, 22.5, 9.5, 15.0, 5.0, 109.5, 0.0, 0.0}));
  EXPECT_EQ(p.m_per_session.m_step_sd, (PerRegion{0.0, 0.075, 0.01, 0.08, 0.05, 0.175, 0.0, 0.04}));
  const PoolingSettings mean = load_config(shipped_config_path()).pooling_footprint_mean;
  EXPECT_EQ(mean.per_step.kbar_chain_sd_pct,
            (PerRegion{5.0, 19.0, 13.0, 13.0, 7.5, 24.5, 0.0, 16.0}));
  EXPECT_EQ(mean.per_step.n_chain_sd, (PerRegion{0.03, 0.08, 0.06, 0.08, 0.05, 0.15, 0.0, 0.075}));
  EXPECT_EQ(mean.per_step.cbar_chain_sd_pct,
            (PerRegion{11.5, 16.5, 17.0, 11.0, 6.0, 48.5, 211.5, 26.0}));
  EXPECT_EQ(mean.per_step.m_chain_sd,
            (PerRegion{0.05, 0.06, 0.035, 0.07, 0.04, 0.05, 0.225, 0.06}));
  EXPECT_EQ(mean.per_step.kbar_step_sd_pct, (PerRegion{0.0, 4.0, 2.5, 13.5, 8.5, 0.0, 0.0, 0.0}));
  EXPECT_EQ(mean.per_step.m_step_sd, (PerRegion{0.0, 0.0, 0.0, 0.125, 0.16, 0.0, 0.0, 0.0}));
  EXPECT_EQ(mean.m_per_session.kbar_chain_sd_pct,
            (PerRegion{5.0, 19.5, 12.5, 12.5, 6.5, 25.5, 7.5, 15.0}));
  EXPECT_EQ(mean.m_per_session.cbar_chain_sd_pct,
            (PerRegion{4.0, 13.5, 22.0, 0.0, 0.0, 69.5, 216.0, 0.0}));
  EXPECT_EQ(mean.m_per_session.m_step_sd,
            (PerRegion{0.01, 0.025, 0.025, 0.04, 0.035, 0.03, 0.0, 0.0}));
  const std::vector<Refusal> cases = {
      {"PoolingNAboveOne", kMain, replace("n_chain_sd = { heel = 0.02", "n_chain_sd = { heel = 2"),
       "pooling.n_chain_sd.heel", "must be in [0, 1], got 2"},
      {"PoolingKbarNegative", kMain, replace("kbar_chain_sd_pct", "met1_2 = 5.5", "met1_2 = -5"),
       "pooling.kbar_chain_sd_pct.met1_2", "must be in [0, 1000], got -5"},
      {"PoolingSharedMCbarTooLarge", kMain,
       replace("[pooling.m_per_session]", "toe2 = 227.5", "toe2 = 1227.5"),
       "pooling.m_per_session.cbar_chain_sd_pct.toe2", "must be in [0, 1000], got 1227.5"},
      {"PoolingSharedMMissing", kMain, erase_from_to("[pooling.m_per_session]", "[wire]"),
       "pooling.m_per_session", "missing"},
      {"PoolingRegionMissing", kMain, replace("m_chain_sd", ", toes3_5 = 0.155", ""),
       "pooling.m_chain_sd.toes3_5", "missing"},
      {"PoolingTableMissing", kMain, erase_from_to("cbar_chain_sd_pct", "m_chain_sd"),
       "pooling.cbar_chain_sd_pct", "missing"},
      {"PoolingStepNegative", kMain, replace("kbar_step_sd_pct", "met1_2 = 10.5", "met1_2 = -1"),
       "pooling.kbar_step_sd_pct.met1_2", "must be in [0, 1000], got -1"},
      {"PoolingSharedMStepAboveOne", kMain,
       replace("[pooling.m_per_session]", "m_step_sd = { heel = 0.000", "m_step_sd = { heel = 1.5"),
       "pooling.m_per_session.m_step_sd.heel", "must be in [0, 1], got 1.5"},
      {"PoolingStepTableMissing", kMain, erase_from_to("n_step_sd", "cbar_step_sd_pct"),
       "pooling.n_step_sd", "missing"},
      {"PoolingFootprintMeanMissing", kMain, erase_from_to("[pooling.footprint_mean]", "[wire]"),
       "pooling.footprint_mean", "missing"},
      {"PoolingFootprintMeanNAboveOne", kMain,
       set_heel("[pooling.footprint_mean]", "n_chain_sd", "1.5"),
       "pooling.footprint_mean.n_chain_sd.heel", "must be in [0, 1], got 1.5"},
      {"PoolingFootprintMeanSharedMStepMissing", kMain,
       replace("[pooling.footprint_mean.m_per_session]", "cbar_step_sd_pct", "cbar_step_sd"),
       "pooling.footprint_mean.m_per_session.cbar_step_sd_pct", "missing"},
  };
  expect_refusals(cases);
}

TEST(Config, LogLevelDefaultsToInfoAndIsRead) {
  EXPECT_EQ(load_config(shipped_config_path()).log.level, "info");
  EXPECT_EQ(LogSettings{}.level, "info");
  for (const std::string& level : log_level_names()) {
    const fs::path dir = copy_config("LogRead-" + level);
    edit_file(dir / kMain, replace("[log]", "level = \"info\"", "level = \"" + level + "\""));
    EXPECT_EQ(load_config(dir / kMain).log.level, level);
  }
}

TEST(Config, LogLevelIsValidated) {
  const std::vector<Refusal> cases = {
      {"LogMissingTable", kMain, truncate_at("[log]\n"), "log", "missing"},
      {"LogMissingLevel", kMain, replace("[log]", "level = \"info\"\n", ""), "log.level",
       "missing"},
      {"LogUnknownLevel", kMain, replace("[log]", "level = \"info\"", "level = \"verbose\""),
       "log.level",
       R"(must be one of "trace", "debug", "info", "warn", "error", "off", got "verbose")"},
      {"LogLevelCapitals", kMain, replace("[log]", "level = \"info\"", "level = \"INFO\""),
       "log.level", R"(got "INFO")"},
      {"LogLevelNotString", kMain, replace("[log]", "level = \"info\"", "level = 2"), "log.level",
       "expected a string, got an integer"},
      {"LogUnknownKey", kMain, replace("[log]\n", "[log]\nfile = \"gaitmon.log\"\n"), "log.file",
       "unknown key"},
  };
  expect_refusals(cases);
}

}  // namespace
}  // namespace gaitmon
