// Segmentation of whole simulated sessions against the simulator's ground truth, all six sizes.
#include "gaitmon/batch.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <ostream>

#include "gaitmon/creep.hpp"
#include "gaitmon/error.hpp"
#include "gaitmon/session.hpp"
#include "gaitmon/simulator.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

struct Case {
  InsoleSize size;
  std::uint64_t seed;
  double body_mass_kg;
};

// gtest prints a case it cannot print as its bytes, padding included.
void PrintTo(const Case& c, std::ostream* os) {
  *os << insole_size_name(c.size) << ", seed " << c.seed << ", " << c.body_mass_kg << " kg";
}

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

  // A step whose 40 N events lie within the debounce of the recording's ends cannot be told
  // whole from cut (nor seen at all if it shows fewer frames than the debounce): either status
  // is right for it, and it may be missing. Every other step must be found, whole.
  const std::int64_t margin = config.segmentation.debounce_frames;
  const std::int64_t last = truth.frames_per_foot - 1;
  for (Foot foot : kFeet) {
    SCOPED_TRACE(std::string("foot ") + std::string(foot_name(foot)));
    int whole = 0;
    int matched = 0;
    for (const auto& expected : truth.steps) {
      if (expected.foot != foot) continue;
      const bool at_edge = expected.partial || expected.heel_strike_frame < margin ||
                           expected.toe_off_frame > last - margin;
      const Step* hit = nullptr;
      for (const auto& s : found) {
        if (s.foot == foot && s.heel_strike_frame <= expected.toe_off_frame &&
            s.toe_off_frame >= expected.heel_strike_frame) {
          EXPECT_EQ(hit, nullptr) << "two steps found for the one at " << expected.t_heel_strike_s;
          hit = &s;
        }
      }
      if (at_edge) continue;
      ++whole;
      ASSERT_NE(hit, nullptr) << "missed the step at " << expected.t_heel_strike_s << " s";
      ++matched;
      EXPECT_EQ(hit->status, StepStatus::Ok) << expected.t_heel_strike_s;
      EXPECT_LE(std::llabs(hit->heel_strike_frame - expected.heel_strike_frame), 1);
      EXPECT_LE(std::llabs(hit->toe_off_frame - expected.toe_off_frame), 1);
      // The bias-removed peak force is the simulated one up to noise and quantisation.
      EXPECT_NEAR(hit->peak_force_n, expected.peak_total_force_n,
                  0.03 * expected.peak_total_force_n);
    }
    EXPECT_GE(whole, 18);
    EXPECT_EQ(matched, whole);
    // No step is invented: every step found overlaps a simulated one, and they are numbered
    // 0, 1, 2, ... in time order.
    int index = 0;
    for (const auto& s : found) {
      if (s.foot != foot) continue;
      EXPECT_EQ(s.index, index++);
      const bool real = std::any_of(truth.steps.begin(), truth.steps.end(), [&](const auto& e) {
        return e.foot == foot && s.heel_strike_frame <= e.toe_off_frame &&
               s.toe_off_frame >= e.heel_strike_frame;
      });
      EXPECT_TRUE(real) << "invented step at frame " << s.heel_strike_frame;
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
  std::string text = test::session_head();
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

TEST(SegmentSession, ARateTooLowForTheConfigsWindowsNamesBoth) {
  Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  // At 10 Hz a swing midpoint lies at most 15 frames from its step: a 20-frame window cannot fit.
  config.segmentation.swing_window_frames = 20;
  config.segmentation.max_gap_s = 0.2;
  const auto dir = test::scratch_dir("batch-rate");
  const auto path =
      test::write_text(dir / "slow.csv", test::session_head("10") + test::session_row("0,L"));
  try {
    segment_session(path, config, [](Step&&) {});
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), path.string());
    EXPECT_NE(std::string(e.what()).find("sample_rate_hz 10 does not fit [segmentation] of " +
                                         config.source.string()),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("swing_window_frames"), std::string::npos) << e.what();
  }
  // The default max_gap_s, 0.055 s, would take every 0.1 s interval for a gap.
  config.segmentation.swing_window_frames = 15;
  config.segmentation.max_gap_s = 0.055;
  try {
    segment_session(path, config, [](Step&&) {});
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("max_gap_s 0.055 s is under 1.5 sample periods (0.15"),
              std::string::npos)
        << e.what();
  }
  config.segmentation.max_gap_s = 0.2;
  std::vector<Step> steps;
  const SegmentedSessionInfo info =
      segment_session(path, config, [&](Step&& step) { steps.push_back(std::move(step)); });
  EXPECT_EQ(info.frames_per_foot[0], 1);
  EXPECT_TRUE(steps.empty());
}

TEST(SegmentSession, AGapRestartsEachFootsSegmentationAndIsCounted) {
  const Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  const auto dir = test::scratch_dir("batch-gap");
  SimulationOptions options;
  options.seed = 3;
  options.duration_s = 10.0;
  const SimulationTruth truth =
      simulate_session(config, options, dir / "session.csv", dir / "truth.json");
  // The probe's session: 100 s pass in both feet's streams at 5 s.
  {
    SessionReader reader(dir / "session.csv");
    SessionWriter writer(dir / "gap.csv", reader.header());
    Frame frame;
    while (reader.next(frame)) {
      if (frame.t_s >= 5.0) frame.t_s = std::round((frame.t_s + 100.0) * 1e6) / 1e6;
      writer.write(frame);
    }
    writer.close();
  }
  std::vector<Step> found;
  const SegmentedSessionInfo info = segment_session(
      dir / "gap.csv", config, [&](Step&& step) { found.push_back(std::move(step)); });
  EXPECT_EQ(info.frames_per_foot[0], truth.frames_per_foot);
  EXPECT_EQ(info.gaps_per_foot[0], 1);
  EXPECT_EQ(info.gaps_per_foot[1], 1);
  ASSERT_FALSE(found.empty());
  for (const Step& s : found) {
    // Stances last about 0.7 s in the simulated walk; none may reach across the gap.
    EXPECT_LT(s.t_toe_off_s - s.t_heel_strike_s, 2.0)
        << foot_name(s.foot) << " step " << s.index << " " << step_status_name(s.status);
  }
}

// A correction reaches every frame before the segmenter sees it: the creep undone at its own
// gain and tau, the same walk's steps come back as without creep, their heel strikes to the frame
// and every reading of their stances to the bit that the second rounding can move. The config's
// [sensor_creep] is that creep for both the simulator and the reader.
TEST(SegmentSession, UndoesTheConfigsCreepAndACorrectionBeforeSegmenting) {
  const Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  const auto dir = test::scratch_dir("batch-correct-frame");
  SimulationOptions options;
  options.size = InsoleSize::S41_42;
  options.seed = 17;
  options.duration_s = 8.0;
  simulate_session(config, options, dir / "clean.csv", dir / "clean.json");
  options.effects = {"sensor_creep"};
  options.effect_params["sensor_creep"] = {{"gain", 0.3}, {"tau_s", 1.0}};
  simulate_session(config, options, dir / "creep.csv", dir / "creep.json");

  const auto steps_of = [&](const char* name, const std::function<void(Frame&)>& correct,
                            const Config& reader) {
    std::vector<Step> steps;
    segment_session(
        dir / name, reader,
        [&](Step&& s) {
          if (s.status == StepStatus::Ok) steps.push_back(std::move(s));
        },
        {}, correct);
    // The feet's steps come interleaved as they end; each foot's in order.
    std::stable_sort(steps.begin(), steps.end(),
                     [](const Step& a, const Step& b) { return a.foot < b.foot; });
    return steps;
  };
  CreepCorrection undo(0.3, 1.0);
  const std::vector<Step> clean = steps_of("clean.csv", {}, config);
  const std::vector<Step> undone = steps_of(
      "creep.csv", [&](Frame& f) { undo.undo(f); }, config);
  const std::vector<Step> as_read = steps_of("creep.csv", {}, config);
  ASSERT_GE(clean.size(), 8u);
  ASSERT_EQ(undone.size(), clean.size());
  for (std::size_t i = 0; i < clean.size(); ++i) {
    EXPECT_EQ(undone[i].foot, clean[i].foot);
    EXPECT_EQ(undone[i].heel_strike_frame, clean[i].heel_strike_frame);
  }
  const auto off_by_more_than_a_bit = [&](const std::vector<Step>& steps) {
    std::size_t off = 0;
    std::size_t all = 0;
    for (std::size_t i = 0; i < std::min(steps.size(), clean.size()); ++i) {
      if (steps[i].heel_strike_frame != clean[i].heel_strike_frame) continue;
      const std::size_t frames = std::min(steps[i].stance.size(), clean[i].stance.size());
      for (std::size_t f = 0; f < frames; ++f) {
        for (std::size_t c = 0; c < clean[i].stance[f].bits.size(); ++c) {
          ++all;
          off += std::abs(steps[i].stance[f].bits[c] - clean[i].stance[f].bits[c]) > 1;
        }
      }
    }
    return static_cast<double>(off) / static_cast<double>(all);
  };
  // As read, a loaded cell reads up to 30 % more (32 % of the readings more than a bit off);
  // undone, none was more than a bit off. The dc bias's share (up to 0.46 bits) and the two
  // roundings could add up to two bits now and then, hence the margin.
  EXPECT_LT(off_by_more_than_a_bit(undone), 0.002);
  EXPECT_GT(off_by_more_than_a_bit(as_read), 0.05);

  Config insoles = config;
  insoles.sensor_creep = {0.3, 1.0};
  options.effects.clear();
  options.effect_params.clear();
  const SimulationTruth truth =
      simulate_session(insoles, options, dir / "insoles.csv", dir / "insoles.json");
  EXPECT_EQ(truth.options.effects, std::vector<std::string>{"sensor_creep"});
  EXPECT_EQ(test::read_text(dir / "insoles.csv"), test::read_text(dir / "creep.csv"));
  const std::vector<Step> configured = steps_of("insoles.csv", {}, insoles);
  ASSERT_EQ(configured.size(), undone.size());
  for (std::size_t i = 0; i < undone.size(); ++i) {
    EXPECT_EQ(configured[i].heel_strike_frame, undone[i].heel_strike_frame);
    ASSERT_EQ(configured[i].stance.size(), undone[i].stance.size());
    for (std::size_t f = 0; f < undone[i].stance.size(); ++f) {
      ASSERT_EQ(configured[i].stance[f].bits, undone[i].stance[f].bits) << "step " << i;
    }
  }
  EXPECT_LT(off_by_more_than_a_bit(configured), 0.002);
}

}  // namespace
}  // namespace gaitmon
