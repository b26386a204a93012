// The chain's SDs measured on simulated sessions: the solver on cases with a closed form, the
// design's sessions, the whole measurement on a few sessions under the sanitizers, and the shipped
// [pooling] and [asymmetry] tables reproduced from the designs the config and README name and
// shown as they are in the README.
#include "gaitmon/calibration.hpp"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <vector>

#include "gaitmon/analysis.hpp"
#include "gaitmon/config.hpp"
#include "gaitmon/error.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

const std::vector<InsoleSize> kThreeSizes = {InsoleSize::S37_38, InsoleSize::S41_42,
                                             InsoleSize::S45_46};

std::vector<ChainSample> plus_minus(double error, double se, double slope = 0.0) {
  return {{error, se, slope}, {-error, se, slope}};
}

// Every sample's z has magnitude error / sqrt(se^2 + (slope m_sd)^2 + sd^2), so where all agree
// the SD with an RMS of 1 is sqrt(error^2 - se^2 - (slope m_sd)^2).
TEST(Calibration, TheSdThatBringsTheRmsOfZToOneHasItsClosedForm) {
  EXPECT_NEAR(*sd_for_unit_rms(plus_minus(2.0, 0.0)), 2.0, 1e-8);
  EXPECT_NEAR(*sd_for_unit_rms(plus_minus(std::sqrt(5.0), 1.0)), 2.0, 1e-8);
  EXPECT_NEAR(*sd_for_unit_rms(plus_minus(std::sqrt(5.0), 1.0, 2.0), 0.5), std::sqrt(3.0), 1e-8);
  // Samples whose own standard errors already cover them need none.
  EXPECT_EQ(*sd_for_unit_rms(plus_minus(0.5, 1.0)), 0.0);
  EXPECT_EQ(*sd_for_unit_rms(plus_minus(std::sqrt(5.0), 1.0, 2.0), 1.0), 0.0);
  EXPECT_FALSE(sd_for_unit_rms({}).has_value());
  // Unequal samples: the mean of z^2, (1 + 9) / (1 + s^2) / 2, is 1 at s = 2.
  EXPECT_NEAR(*sd_for_unit_rms({{1.0, 1.0, 0.0}, {3.0, 1.0, 0.0}}), 2.0, 1e-8);
  EXPECT_NEAR(rms_z({{1.0, 1.0, 0.0}, {3.0, 1.0, 0.0}}, 2.0), 1.0, 1e-12);
  EXPECT_TRUE(std::isnan(rms_z({}, 1.0)));
}

TEST(Calibration, RoundsUpToTheStepAndNeverBelowZero) {
  EXPECT_DOUBLE_EQ(round_up_to(4.01, 0.5), 4.5);
  EXPECT_DOUBLE_EQ(round_up_to(4.0, 0.5), 4.0);
  EXPECT_DOUBLE_EQ(round_up_to(4.0 + 1e-12, 0.5), 4.0);
  EXPECT_DOUBLE_EQ(round_up_to(0.0501, 0.005), 0.055);
  EXPECT_FALSE(std::signbit(round_up_to(0.0, 0.5)));
}

// m's SD comes first and, rounded, reaches the others through their slopes on a shared m:
// kbar's samples of 100 ln error 0.05 with a slope of 1 on m whose own error is 0.04 (SD 0.04,
// rounded to 0.04) leave sqrt(0.05^2 - 0.04^2) = 0.03, 3.0 %; without the slope 5.0 %. A step's
// own SD is what its samples need beside that chain SD: errors 0.13 with standard errors 0.05 need
// 0.12 in all, so sqrt(0.12^2 - 0.05^2) = 0.109 of their own, 11.0 % rounded up.
TEST(Calibration, MsRoundedSdReachesTheOthersThroughTheirSlopes) {
  ChainSamples samples;
  samples.pooled[0][3] = plus_minus(0.04, 0.0);
  samples.pooled[0][0] = plus_minus(0.05, 0.0, 1.0);
  samples.pooled[1][3] = plus_minus(0.04, 0.0);
  samples.pooled[1][0] = plus_minus(0.05, 0.0);
  samples.feet[0][1] = plus_minus(0.021, 0.0);
  samples.steps[1][0] = plus_minus(0.13, 0.05);
  samples.steps[1][1] = plus_minus(0.01, 0.05);
  const MeasuredChainSds sds = measure_chain_sds(samples);
  EXPECT_DOUBLE_EQ(*sds.step[0][1], 11.0);
  EXPECT_DOUBLE_EQ(*sds.step[1][1], 0.0) << "covered by the steps' own standard errors";
  EXPECT_FALSE(sds.step[0][0].has_value());
  EXPECT_DOUBLE_EQ(*sds.chain[3][0], 0.04);
  EXPECT_DOUBLE_EQ(*sds.chain[0][0], 3.0);
  EXPECT_DOUBLE_EQ(*sds.chain[0][1], 5.0);
  EXPECT_DOUBLE_EQ(*sds.pair[1][0], 2.5);
  EXPECT_FALSE(sds.chain[1][0].has_value());
  EXPECT_FALSE(sds.pair[0][0].has_value());
}

TEST(Calibration, TheDesignCrossesSizesWithSeedsAndSpreadsTheMassOverTheSeeds) {
  CalibrationDesign design;
  design.sizes = {InsoleSize::S35_36, InsoleSize::S45_46};
  design.first_seed = 1;
  design.last_seed = 20;
  ASSERT_EQ(design.session_count(), 40u);
  EXPECT_EQ(design.size_of(19), InsoleSize::S35_36);
  EXPECT_EQ(design.size_of(20), InsoleSize::S45_46);
  EXPECT_EQ(design.seed_of(20), 1u);
  EXPECT_EQ(design.seed_of(39), 20u);
  EXPECT_DOUBLE_EQ(design.body_mass_kg_of(0), 50.0);
  EXPECT_DOUBLE_EQ(design.body_mass_kg_of(1), 52.1);  // 50 + 40 / 19, to 0.1 kg
  EXPECT_DOUBLE_EQ(design.body_mass_kg_of(39), 90.0);
  design.last_seed = 1;
  EXPECT_DOUBLE_EQ(design.body_mass_kg_of(1), 50.0);

  const auto refused = [](CalibrationDesign d, const std::string& says) {
    try {
      d.check();
      ADD_FAILURE() << "accepted: " << says;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
  };
  CalibrationDesign good;
  good.sizes = {InsoleSize::S41_42};
  EXPECT_NO_THROW(good.check());
  refused({}, "sizes: none given");
  CalibrationDesign d = good;
  d.first_seed = 5;
  d.last_seed = 4;
  refused(d, "seeds: the first (5) is after the last (4)");
  d = good;
  d.duration_s = 0.0;
  refused(d, "duration_s must be in (0, 86400]");
  d = good;
  d.min_body_mass_kg = 80.0;
  d.max_body_mass_kg = 60.0;
  refused(d, "body mass must be 0 < min <= max <= 300 kg, got 80 to 60");
}

double rms(const std::vector<ChainSample>& samples, double sd, double m_sd) {
  double sum = 0.0;
  for (const ChainSample& s : samples) {
    const double v =
        s.se_steps * s.se_steps + s.slope_on_shared_m * s.slope_on_shared_m * m_sd * m_sd + sd * sd;
    sum += s.error * s.error / v;
  }
  return std::sqrt(sum / static_cast<double>(samples.size()));
}

// On a few short sessions, run under the sanitizers too: every region with pools has samples of
// all four parameters, only steps at a shared m have slopes on it, and each measured SD is the
// least multiple of its step whose z (computed here) has an RMS of at most 1.
TEST(Calibration, EachMeasuredSdIsTheLeastStepThatBringsTheRmsOfZToOne) {
  const Config config = load_config(default_config_path());
  CalibrationDesign design;
  design.sizes = {InsoleSize::S41_42};
  design.first_seed = 1;
  design.last_seed = 2;
  design.duration_s = 10.0;
  std::vector<double> progress;
  const auto scratch = test::scratch_dir("calibration-few");
  const CalibrationSamples samples =
      collect_chain_samples(config, design, scratch, [&](double f) { progress.push_back(f); });
  ASSERT_EQ(samples.sessions, 2u);
  ASSERT_FALSE(progress.empty());
  EXPECT_DOUBLE_EQ(progress.back(), 1.0);
  EXPECT_TRUE(std::filesystem::is_empty(scratch)) << "the simulated sessions are left behind";
  const auto& heel = samples.per_step.pooled[0];
  ASSERT_EQ(heel[0].size(), 2u);
  for (const auto& p : heel) {
    EXPECT_EQ(p.size(), 2u);
    for (const ChainSample& s : p) EXPECT_EQ(s.slope_on_shared_m, 0.0);
  }
  ASSERT_EQ(samples.m_per_session.pooled[0][2].size(), 2u);
  EXPECT_NE(samples.m_per_session.pooled[0][2][0].slope_on_shared_m, 0.0);
  EXPECT_EQ(samples.m_per_session.pooled[0][3][0].slope_on_shared_m, 0.0);
  ASSERT_EQ(samples.per_step.feet[0][0].size(), 2u);
  // Each step's own estimate, once per step with one: more than the sessions' pools.
  EXPECT_GT(samples.per_step.steps[0][0].size(), 10u);
  for (const ChainSample& s : samples.per_step.steps[0][2]) EXPECT_EQ(s.slope_on_shared_m, 0.0);
  EXPECT_NE(samples.m_per_session.steps[0][2].front().slope_on_shared_m, 0.0);
  EXPECT_EQ(samples.m_per_session.steps[0][3].front().slope_on_shared_m, 0.0);

  for (const ChainSamples* mode : {&samples.per_step, &samples.m_per_session}) {
    const MeasuredChainSds sds = measure_chain_sds(*mode);
    for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
      SCOPED_TRACE(std::string(region_name(kRegions[ri])));
      const double m_sd = sds.chain[3][ri].value_or(0.0);
      for (std::size_t p = 0; p < 4; ++p) {
        const auto& s = mode->pooled[ri][p];
        ASSERT_EQ(sds.chain[p][ri].has_value(), !s.empty());
        if (s.empty()) continue;
        const double scale = (p == 0 || p == 2) ? 100.0 : 1.0;
        const double step = scale == 100.0 ? 0.5 : 0.005;
        const double sd = *sds.chain[p][ri] / scale;
        const double own_m = p == 3 ? 0.0 : m_sd;
        EXPECT_LE(rms(s, sd, own_m), 1.0 + 1e-9);
        if (*sds.chain[p][ri] > 0.0) {
          EXPECT_GT(rms(s, sd - step / scale, own_m), 1.0);
        }
      }
      // A step's own SD, with the chain's: the least step of it that brings the steps' z to 1.
      for (std::size_t p = 0; p < 4; ++p) {
        const auto& s = mode->steps[ri][p];
        ASSERT_EQ(sds.step[p][ri].has_value(), !s.empty());
        if (s.empty()) continue;
        const double scale = (p == 0 || p == 2) ? 100.0 : 1.0;
        const double step = scale == 100.0 ? 0.5 : 0.005;
        const double chain = sds.chain[p][ri].value_or(0.0) / scale;
        const double own = *sds.step[p][ri] / scale;
        const double own_m = p == 3 ? 0.0 : m_sd;
        EXPECT_LE(rms(s, std::hypot(chain, own), own_m), 1.0 + 1e-9);
        if (own > 0.0) {
          EXPECT_GT(rms(s, std::hypot(chain, own - step / scale), own_m), 1.0);
        }
      }
      for (std::size_t p = 0; p < 2; ++p) {
        const auto& s = mode->feet[ri][p];
        if (s.empty()) continue;
        const double sd = *sds.pair[p][ri] / 100.0;
        EXPECT_LE(rms(s, sd, 0.0), 1.0 + 1e-9);
        if (sd > 0.0) {
          EXPECT_GT(rms(s, sd - 0.005, 0.0), 1.0);
        }
      }
    }
  }
}

// Per entry, the larger of what the designs measured; where none measured it (a region no session
// pooled or compared), toe1's.
std::array<double, kRegionCount> larger_of(
    const std::vector<const std::array<std::optional<double>, kRegionCount>*>& measured) {
  std::array<double, kRegionCount> out{};
  const std::size_t toe1 = index_of(Region::Toe1);
  for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
    std::optional<double> larger;
    for (const auto* m : measured) {
      if ((*m)[ri]) larger = std::max(larger.value_or(0.0), *(*m)[ri]);
    }
    EXPECT_TRUE(larger || ri > toe1) << region_name(kRegions[ri]) << " was measured in no design";
    out[ri] = larger ? *larger : out[toe1];
  }
  return out;
}

void expect_shipped(const std::string& table, const std::array<double, kRegionCount>& shipped,
                    const std::array<double, kRegionCount>& expected) {
  std::printf("%-42s", table.c_str());
  for (std::size_t ri = 0; ri < kRegionCount; ++ri)
    std::printf(" %g/%g", shipped[ri], expected[ri]);
  std::printf("  (shipped/measured)\n");
  for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
    EXPECT_NEAR(shipped[ri], expected[ri], 1e-9) << table << " " << region_name(kRegions[ri]);
  }
}

// One of the README's tables of the shipped SDs: the `occurrence`-th (from 0) whose header starts
// with `header`, each row's label and the first number of each region's cell (what follows it in
// brackets is an earlier stop's value). Empty where the table is not there as expected.
std::vector<std::array<double, kRegionCount>> readme_table(const std::string& readme,
                                                           const std::string& header,
                                                           int occurrence,
                                                           const std::vector<std::string>& labels) {
  std::istringstream in(readme);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) {
    lines.push_back(line.substr(std::min(line.find_first_not_of(' '), line.size())));
  }
  std::size_t at = 0;
  for (int seen = -1; at < lines.size(); ++at) {
    if (lines[at].starts_with(header) && ++seen == occurrence) break;
  }
  if (at + 1 + labels.size() >= lines.size()) return {};
  std::vector<std::array<double, kRegionCount>> rows;
  for (std::size_t k = 0; k < labels.size(); ++k) {
    std::vector<std::string> cells;
    std::istringstream row(lines[at + 2 + k]);
    for (std::string cell; std::getline(row, cell, '|');) cells.push_back(cell);
    if (cells.size() != kRegionCount + 2 || cells[1] != " " + labels[k] + " ") return {};
    std::array<double, kRegionCount> values{};
    for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
      const char* text = cells[ri + 2].c_str();
      char* end = nullptr;
      values[ri] = std::strtod(text, &end);
      if (end == text) return {};
    }
    rows.push_back(values);
  }
  return rows;
}

std::string table_key(AreaSource area, bool shared_m, const char* section, const char* key) {
  return chain_table_name(section, area, shared_m) + " " + key;
}

// The README's headers of the chain's tables, per area.
std::string readme_chain_header(AreaSource area) {
  return area == AreaSource::FootprintMean
             ? "| footprint-mean | heel | midfoot posterior | midfoot anterior | met1_2 |"
             : "| | heel | midfoot posterior | midfoot anterior | met1_2 |";
}

std::string readme_pair_header(AreaSource area, bool shared_m) {
  return fmt::format("| SD of 100 ln(right / left){}{} |",
                     area == AreaSource::FootprintMean ? ", footprint-mean" : "",
                     shared_m ? ", at one m" : "");
}

// The README shows the shipped [pooling] and [asymmetry] chain SDs, and their footprint_mean
// tables, as tables ("How honest the standard errors are", "Left against right", "How the cells
// read"); a change of the config's tables that leaves them behind fails here.
TEST(Calibration, TheReadmesTablesOfTheShippedSdsAreTheConfigs) {
  std::ifstream file(test::source_dir() / "README.md");
  ASSERT_TRUE(file) << "no README.md in " << test::source_dir();
  const std::string readme{std::istreambuf_iterator<char>(file), {}};
  const Config config = load_config(default_config_path());
  const std::vector<std::string> kChainLabels = {"kbar (%)", "n", "cbar (%)", "m"};
  for (const AreaSource area : {AreaSource::Footprint, AreaSource::FootprintMean}) {
    for (const bool shared_m : {false, true}) {
      SCOPED_TRACE(table_key(area, shared_m, "pooling", "*_chain_sd"));
      const PoolingSettings& tables = pooling_tables(config, area);
      const ChainSds& chain = shared_m ? tables.m_per_session : tables.per_step;
      const auto rows =
          readme_table(readme, readme_chain_header(area), shared_m ? 1 : 0, kChainLabels);
      ASSERT_EQ(rows.size(), 4U) << "the README's table of the chain's SDs is not where expected";
      const std::array<const std::array<double, kRegionCount>*, 4> shipped = {
          &chain.kbar_chain_sd_pct, &chain.n_chain_sd, &chain.cbar_chain_sd_pct, &chain.m_chain_sd};
      for (std::size_t k = 0; k < 4; ++k) {
        for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
          EXPECT_EQ(rows[k][ri], (*shipped[k])[ri])
              << kChainLabels[k] << " " << region_name(kRegions[ri]);
        }
      }
    }
    for (const bool shared_m : {false, true}) {
      SCOPED_TRACE(table_key(area, shared_m, "asymmetry", "*_pair_sd_pct"));
      const AsymmetrySettings& tables = asymmetry_tables(config, area);
      const PairSds& pair = shared_m ? tables.m_per_session : tables.per_step;
      const auto rows =
          readme_table(readme, readme_pair_header(area, shared_m), 0, {"kbar", "cbar"});
      ASSERT_EQ(rows.size(), 2U) << "the README's table of the pair's SDs is not where expected";
      for (std::size_t ri = 0; ri < kRegionCount; ++ri) {
        EXPECT_EQ(rows[0][ri], pair.kbar_pair_sd_pct[ri]) << "kbar " << region_name(kRegions[ri]);
        EXPECT_EQ(rows[1][ri], pair.cbar_pair_sd_pct[ri]) << "cbar " << region_name(kRegions[ri]);
      }
    }
  }
}

// The shipped tables are what `gaitmon calibrate --designs config/calibration_designs.toml`
// measures (README, "Measuring the chain's SDs"), each entry the larger of two designs:
// - [pooling] and [pooling.m_per_session], the chain's and the steps' own: 120 sessions of 30 s,
//   six sizes, 50-90 kg, seeds 1-20 (the command's defaults), and 60 sessions of 30 s of 60-kg
//   walkers, sizes 37-38, 41-42 and 45-46, seeds 1-20;
// - [asymmetry] and [asymmetry.m_per_session]: 90 sessions of 60 s of 60-kg walkers, sizes 37-38,
//   41-42 and 45-46, seeds 1-30, and 90 sessions of 60 s, six sizes, 50-90 kg, seeds 1-15;
// - their footprint_mean tables: the same four designs on cells that average the pressure over
//   their area (the coverage raster), analysed with footprint-mean.
// The designs file is checked to hold those. A change of the fit or the chain that moves the
// tables fails here: measure again with the command and update config/gaitmon.toml and the README.
class ShippedTables : public ::testing::TestWithParam<Rasterisation> {};

}  // namespace

// For ctest's and gtest's listings, which print a parameter.
void PrintTo(Rasterisation raster, std::ostream* out) {
  *out << rasterisation_name(raster);
}

namespace {

TEST_P(ShippedTables, AreWhatTheCommandMeasuresOnTheirDesigns) {
  const Rasterisation raster = GetParam();
  const AreaSource area =
      raster == Rasterisation::Coverage ? AreaSource::FootprintMean : AreaSource::Footprint;
  const std::vector<CalibrationDesignEntry> all_designs =
      load_calibration_designs(test::source_dir() / "config" / "calibration_designs.toml");
  ASSERT_EQ(all_designs.size(), 8U);
  std::vector<CalibrationDesignEntry> designs;
  for (const CalibrationDesignEntry& entry : all_designs) {
    if (entry.design.rasterisation == raster) designs.push_back(entry);
  }
  CalibrationDesign all;
  all.sizes = {kInsoleSizes.begin(), kInsoleSizes.end()};
  CalibrationDesign walkers_60kg;
  walkers_60kg.sizes = kThreeSizes;
  walkers_60kg.min_body_mass_kg = walkers_60kg.max_body_mass_kg = 60.0;
  CalibrationDesign feet_60kg = walkers_60kg;
  feet_60kg.last_seed = 30;
  feet_60kg.duration_s = 60.0;
  CalibrationDesign feet_all = all;
  feet_all.last_seed = 15;
  feet_all.duration_s = 60.0;
  const struct {
    const CalibrationDesign* design;
    bool pooling;
  } named[] = {{&all, true}, {&walkers_60kg, true}, {&feet_60kg, false}, {&feet_all, false}};
  ASSERT_EQ(designs.size(), 4U);
  for (std::size_t i = 0; i < designs.size(); ++i) {
    const CalibrationDesign& d = designs[i].design;
    const CalibrationDesign& n = *named[i].design;
    SCOPED_TRACE(fmt::format("design {} of the {} raster", i + 1, rasterisation_name(raster)));
    EXPECT_EQ(d.sizes, n.sizes);
    EXPECT_EQ(d.first_seed, n.first_seed);
    EXPECT_EQ(d.last_seed, n.last_seed);
    EXPECT_EQ(d.duration_s, n.duration_s);
    EXPECT_EQ(d.min_body_mass_kg, n.min_body_mass_kg);
    EXPECT_EQ(d.max_body_mass_kg, n.max_body_mass_kg);
    EXPECT_EQ(d.noise_sd_bits, n.noise_sd_bits);
    EXPECT_EQ(d.max_bias_bits, n.max_bias_bits);
    EXPECT_EQ(d.placement_sd_mm, n.placement_sd_mm);
    EXPECT_EQ(designs[i].pooling, named[i].pooling);
    EXPECT_EQ(designs[i].asymmetry, !named[i].pooling);
  }
  if (test::kSanitized) {
    GTEST_SKIP() << "360 simulated sessions take too long under the sanitizers; the measurement's "
                    "code runs under them in EachMeasuredSdIsTheLeastStepThatBringsTheRmsOfZToOne";
  }

  const Config config = load_config(default_config_path());
  const auto scratch =
      test::scratch_dir("calibration-designs-" + std::string(rasterisation_name(raster)));
  std::vector<CalibrationSamples> samples;
  for (const CalibrationDesignEntry& entry : designs) {
    samples.push_back(collect_chain_samples(config, entry.design, scratch));
  }
  const char* kChainNames[] = {"kbar_chain_sd_pct", "n_chain_sd", "cbar_chain_sd_pct",
                               "m_chain_sd"};
  const char* kStepNames[] = {"kbar_step_sd_pct", "n_step_sd", "cbar_step_sd_pct", "m_step_sd"};
  const char* kPairNames[] = {"kbar_pair_sd_pct", "cbar_pair_sd_pct"};
  for (const bool shared_m : {false, true}) {
    std::vector<MeasuredChainSds> pooling, asymmetry;
    for (std::size_t i = 0; i < designs.size(); ++i) {
      const MeasuredChainSds sds =
          measure_chain_sds(shared_m ? samples[i].m_per_session : samples[i].per_step);
      if (designs[i].pooling) pooling.push_back(sds);
      if (designs[i].asymmetry) asymmetry.push_back(sds);
    }
    const PoolingSettings& tables = pooling_tables(config, area);
    const ChainSds& chain = shared_m ? tables.m_per_session : tables.per_step;
    const std::array<const std::array<double, kRegionCount>*, 4> chain_shipped = {
        &chain.kbar_chain_sd_pct, &chain.n_chain_sd, &chain.cbar_chain_sd_pct, &chain.m_chain_sd};
    const std::array<const std::array<double, kRegionCount>*, 4> step_shipped = {
        &chain.kbar_step_sd_pct, &chain.n_step_sd, &chain.cbar_step_sd_pct, &chain.m_step_sd};
    for (std::size_t k = 0; k < 4; ++k) {
      expect_shipped(table_key(area, shared_m, "pooling", kChainNames[k]), *chain_shipped[k],
                     larger_of({&pooling[0].chain[k], &pooling[1].chain[k]}));
      expect_shipped(table_key(area, shared_m, "pooling", kStepNames[k]), *step_shipped[k],
                     larger_of({&pooling[0].step[k], &pooling[1].step[k]}));
    }
    const AsymmetrySettings& pair_tables = asymmetry_tables(config, area);
    const PairSds& pair = shared_m ? pair_tables.m_per_session : pair_tables.per_step;
    const std::array<const std::array<double, kRegionCount>*, 2> pair_shipped = {
        &pair.kbar_pair_sd_pct, &pair.cbar_pair_sd_pct};
    for (std::size_t k = 0; k < 2; ++k) {
      expect_shipped(table_key(area, shared_m, "asymmetry", kPairNames[k]), *pair_shipped[k],
                     larger_of({&asymmetry[0].pair[k], &asymmetry[1].pair[k]}));
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Calibration, ShippedTables,
                         ::testing::Values(Rasterisation::CellCentre, Rasterisation::Coverage),
                         [](const auto& info) {
                           return info.param == Rasterisation::Coverage ? "CoverageRaster"
                                                                        : "CentreRaster";
                         });

// A designs file with a mistake names the file, the key and its line, and says why.
TEST(Calibration, ADesignsFileWithAMistakeNamesTheFileTheKeyAndTheLine) {
  const std::string good =
      "[[design]]\ntables = [\"pooling\"]\nsizes = [\"41-42\"]\nseeds = [1, 2]\n"
      "duration_s = 10\nbody_mass_kg = [60, 60]\n";
  const auto dir = test::scratch_dir("calibration-designs-file");
  const auto ok = load_calibration_designs(test::write_text(dir / "good.toml", good));
  ASSERT_EQ(ok.size(), 1U);
  EXPECT_TRUE(ok[0].pooling);
  EXPECT_FALSE(ok[0].asymmetry);
  EXPECT_EQ(ok[0].design.sizes, std::vector<InsoleSize>{InsoleSize::S41_42});
  EXPECT_EQ(ok[0].design.last_seed, 2U);
  EXPECT_EQ(ok[0].design.noise_sd_bits, CalibrationDesign{}.noise_sd_bits);
  EXPECT_EQ(ok[0].design.rasterisation, Rasterisation::CellCentre);
  const auto coverage = load_calibration_designs(
      test::write_text(dir / "coverage.toml", good + "rasterisation = \"coverage\"\n"));
  ASSERT_EQ(coverage.size(), 1U);
  EXPECT_EQ(coverage[0].design.rasterisation, Rasterisation::Coverage);

  const struct {
    const char* name;
    std::string text;
    const char* key;
    const char* reason;
  } cases[] = {
      {"no design", "title = 1\n", "design", "missing"},
      {"unknown key", good + "noise = 1\n", "design[1].noise", "unknown key (line 7)"},
      {"a table's name", "[[design]]\ntables = [\"pool\"]\n", "design[1].tables",
       R"(expected "pooling" or "asymmetry" (line 2))"},
      {"a table twice", "[[design]]\ntables = [\"pooling\", \"pooling\"]\n", "design[1].tables",
       "twice"},
      {"a size", "[[design]]\ntables = [\"pooling\"]\nsizes = [\"40-41\"]\n", "design[1].sizes",
       "expected an insole size such as \"41-42\" (line 3)"},
      {"seeds reversed",
       "[[design]]\ntables = [\"pooling\"]\nsizes = [\"41-42\"]\nseeds = [5, 1]\n",
       "design[1].seeds", "the first (5) is after the last (1) (line 4)"},
      {"one seed", "[[design]]\ntables = [\"pooling\"]\nsizes = [\"41-42\"]\nseeds = [5]\n",
       "design[1].seeds", "expected [first, last], got 1 value(s)"},
      {"a short session",
       "[[design]]\ntables = [\"asymmetry\"]\nsizes = [\"41-42\"]\nseeds = [1, 2]\n"
       "duration_s = 2\n",
       "design[1].duration_s", "must be in [5, 3600], got 2 (line 5)"},
      {"a second design missing its mass",
       good + "[[design]]\ntables = [\"asymmetry\"]\n"
              "sizes = [\"41-42\"]\nseeds = [1, 2]\nduration_s = 10\n",
       "design[2].body_mass_kg", "missing"},
      {"a raster", good + "rasterisation = \"cells\"\n", "design[1].rasterisation",
       R"(must be "centre" or "coverage", got "cells" (line 7))"},
      {"bad syntax", "[[design]\n", "(syntax)", "line 1"},
  };
  for (const auto& c : cases) {
    const auto path = test::write_text(dir / "bad.toml", c.text);
    try {
      load_calibration_designs(path);
      ADD_FAILURE() << c.name << ": no ConfigError";
    } catch (const ConfigError& e) {
      EXPECT_EQ(e.file(), path.string()) << c.name;
      EXPECT_EQ(e.key(), c.key) << c.name << ": " << e.what();
      EXPECT_NE(e.reason().find(c.reason), std::string::npos) << c.name << ": " << e.what();
    }
  }
}

}  // namespace
}  // namespace gaitmon
