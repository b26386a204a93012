// Segmentation of whole simulated sessions against the simulator's ground truth, all six sizes.
#include "gaitmon/batch.hpp"

#include <gtest/gtest.h>

#include <cstdlib>

#include "gaitmon/error.hpp"
#include "gaitmon/simulator.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

struct Case {
  InsoleSize size;
  std::uint64_t seed;
  double body_mass_kg;
};

class SimulatedSegmentation : public ::testing::TestWithParam<Case> {};

TEST_P(SimulatedSegmentation, FindsEveryStepWithinOneFrame) {
  const Case c = GetParam();
  const Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  const auto dir = test::scratch_dir("batch-" + std::string(insole_size_name(c.size)) + "-" +
                                     std::to_string(c.seed));
  SimulationOptions options;
  options.size = c.size;
  options.seed = c.seed;
  options.duration_s = 25.0;
  options.body_mass_kg = c.body_mass_kg;
  const SimulationTruth truth =
      simulate_session(config, options, dir / "session.csv", dir / "truth.json");

  std::vector<Step> found;
  const SegmentedSessionInfo info = segment_session(
      dir / "session.csv", config, [&](Step&& step) { found.push_back(std::move(step)); });
  EXPECT_EQ(info.frames_per_foot[0], truth.frames_per_foot);
  EXPECT_EQ(info.frames_per_foot[1], truth.frames_per_foot);

  for (Foot foot : kFeet) {
    std::vector<const SimulatedStep*> expected;
    for (const auto& s : truth.steps) {
      if (s.foot == foot) expected.push_back(&s);
    }
    std::vector<const Step*> got;
    for (const auto& s : found) {
      if (s.foot == foot) got.push_back(&s);
    }
    ASSERT_EQ(got.size(), expected.size()) << "foot " << foot_name(foot);
    ASSERT_GE(expected.size(), 15u);
    for (std::size_t i = 0; i < got.size(); ++i) {
      SCOPED_TRACE(std::string("foot ") + std::string(foot_name(foot)) + " step " +
                   std::to_string(i));
      EXPECT_EQ(got[i]->index, static_cast<int>(i));
      EXPECT_EQ(got[i]->status == StepStatus::Incomplete, expected[i]->partial);
      if (expected[i]->partial) continue;
      EXPECT_LE(std::llabs(got[i]->heel_strike_frame - expected[i]->heel_strike_frame), 1);
      EXPECT_LE(std::llabs(got[i]->toe_off_frame - expected[i]->toe_off_frame), 1);
      // The bias-removed peak force is the simulated one up to noise and quantisation.
      EXPECT_NEAR(got[i]->peak_force_n, expected[i]->peak_total_force_n,
                  0.03 * expected[i]->peak_total_force_n);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(
    AllSizes, SimulatedSegmentation,
    ::testing::Values(Case{InsoleSize::S35_36, 1, 50}, Case{InsoleSize::S35_36, 7, 58},
                      Case{InsoleSize::S37_38, 2, 55}, Case{InsoleSize::S37_38, 8, 65},
                      Case{InsoleSize::S39_40, 3, 75}, Case{InsoleSize::S39_40, 9, 62},
                      Case{InsoleSize::S41_42, 4, 85}, Case{InsoleSize::S41_42, 10, 78},
                      Case{InsoleSize::S43_44, 5, 83}, Case{InsoleSize::S43_44, 11, 95},
                      Case{InsoleSize::S45_46, 6, 87}, Case{InsoleSize::S45_46, 12, 100}),
    [](const auto& info) {
      std::string name(insole_size_name(info.param.size));
      name[2] = '_';
      return "size" + name + "_seed" + std::to_string(info.param.seed);
    });

TEST(SegmentSession, ReportsTheFileAndLineOfABadFrame) {
  const Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  const auto dir = test::scratch_dir("batch-bad");
  std::string text =
      "# gaitmon-session: 1\n# insole_size: 35-36\n# sample_rate_hz: 100\n# sensors: 93\nt_s,foot";
  for (int i = 1; i <= 93; ++i) text += ",s" + std::to_string(i);
  text += "\n";
  for (int k = 0; k < 3; ++k) {
    text += std::to_string(0.01 * k) + ",L";
    for (int i = 1; i <= 93; ++i) text += k == 2 && i == 40 ? ",256" : ",0";
    text += "\n";
  }
  const auto path = test::write_text(dir / "bad.csv", text);
  try {
    segment_session(path, config, [](Step&&) {});
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.line(), 8u);
    EXPECT_NE(std::string(e.what()).find("bad.csv"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace gaitmon
