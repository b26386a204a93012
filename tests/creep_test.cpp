// CreepCorrection: the exact inverse of the simulator's creep, frame by frame.
#include "gaitmon/creep.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <stdexcept>
#include <vector>

#include "gaitmon/segmentation.hpp"
#include "gaitmon/simulator.hpp"

namespace gaitmon {
namespace {

// A load that rises, holds and leaves, at uneven frame spacing, through the simulator's creep and
// back: what each cell read before the creep, to rounding.
TEST(CreepCorrection, UndoesTheSimulatorsCreepExactly) {
  auto creep = make_simulation_effect("sensor_creep", {{"gain", 0.35}, {"tau_s", 0.8}});
  CreepCorrection undo(0.35, 0.8);
  double t = 0.0;
  double largest_change = 0.0;
  for (int k = 0; k < 400; ++k) {
    t += (k % 3 == 0) ? 0.02 : 0.01;
    for (std::size_t sensor = 0; sensor < 3; ++sensor) {
      for (Foot foot : {Foot::Left, Foot::Right}) {
        const double load = (k > 50 && k < 250) ? 40.0 * (1.0 + sensor) * std::sin(0.01 * k) : 0.0;
        const double read = creep->sensor_bits({foot, sensor, t}, load);
        largest_change = std::max(largest_change, std::abs(read - load));
        EXPECT_NEAR(undo.undo(foot, sensor, t, read), load, 1e-9 * (1.0 + std::abs(load)));
      }
    }
  }
  // The creep was there to undo: up to a third of the largest load.
  EXPECT_GT(largest_change, 20.0);
}

// A held load reads (1 + beta) of itself after a few tau; a constant bias the creep never saw
// comes back as bias / (1 + beta), a constant the steps' zeroing takes off.
TEST(CreepCorrection, AHeldReadingComesBackAsItsShareOfOnePlusTheGain) {
  CreepCorrection undo(0.25, 0.5);
  double out = 0.0;
  for (int k = 0; k <= 1000; ++k) out = undo.undo(Foot::Left, 7, 0.01 * k, 125.0);
  EXPECT_NEAR(out, 100.0, 1e-6);
  // Gain 0 leaves the readings as they are.
  CreepCorrection none(0.0, 1.0);
  EXPECT_DOUBLE_EQ(none.undo(Foot::Right, 0, 0.0, 17.0), 17.0);
  EXPECT_DOUBLE_EQ(none.undo(Foot::Right, 0, 0.5, 23.0), 23.0);
}

TEST(CreepCorrection, AFrameIsUndoneToWholeBitsWithinTheInsolesRange) {
  CreepCorrection undo(0.4, 1.0);
  Frame frame{0.0, Foot::Left, {0, 255, 10}};
  undo.undo(frame);
  EXPECT_EQ(frame.bits, (std::vector<std::uint8_t>{0, 255, 10}));  // the first frame: no lag yet
  for (int k = 1; k <= 500; ++k) {
    frame = {0.01 * k, Foot::Left, {0, 255, 140}};
    undo.undo(frame);
  }
  // 255 held reads 255 / 1.4 = 182.1; 140 held reads 100.
  EXPECT_EQ(frame.bits, (std::vector<std::uint8_t>{0, 182, 100}));
}

TEST(CreepCorrection, RefusesAGainOrTauOutsideItsRangeAndTimeGoingBack) {
  EXPECT_THROW(CreepCorrection(-0.1, 1.0), std::invalid_argument);
  EXPECT_THROW(CreepCorrection(0.1, 0.0), std::invalid_argument);
  EXPECT_THROW(CreepCorrection(0.1, NAN), std::invalid_argument);
  EXPECT_THROW(CreepCorrection(INFINITY, 1.0), std::invalid_argument);
  CreepCorrection undo(0.1, 1.0);
  undo.undo(Foot::Left, 0, 1.0, 5.0);
  EXPECT_THROW(undo.undo(Foot::Left, 0, 0.5, 5.0), std::invalid_argument);
  EXPECT_THROW(undo.undo(Foot::Left, 0, NAN, 5.0), std::invalid_argument);
  // Each foot and cell keeps its own time.
  EXPECT_NO_THROW(undo.undo(Foot::Right, 0, 0.5, 5.0));
  EXPECT_NO_THROW(undo.undo(Foot::Left, 1, 0.5, 5.0));
}

// The config's [sensor_creep]: gain 0 is no correction at all, so a config without creep leaves
// every reading as it was read rather than rounding it again.
TEST(CreepCorrection, OfTheConfigIsNoneAtGainZero) {
  EXPECT_FALSE(creep_correction_of(SensorCreepSettings{0.0, 3.0}).has_value());
  const std::optional<CreepCorrection> creep = creep_correction_of(SensorCreepSettings{0.3, 2.0});
  ASSERT_TRUE(creep.has_value());
  EXPECT_DOUBLE_EQ(creep->gain(), 0.3);
  EXPECT_DOUBLE_EQ(creep->tau_s(), 2.0);
}

// A cell counts where some stance frame read 2 bits or more over its zero, and rests at 0 where
// that zero is under half a bit. Four cells over two steps, worked by hand: step 1 loads cells 0
// (zero 0.2: at 0) and 3 (zero 3.0), not cell 1 (1.4 bits over its zero of 0.6) nor cell 2 (never
// over 0); step 2 loads cells 1 (zero 0.4: at 0) and 2 (zero 0.5: not under half a bit). 2 of 4.
TEST(LoadedCellsAtZero, CountsTheLoadedCellsWhoseZeroIsUnderHalfABit) {
  const auto frame = [](std::vector<std::uint8_t> bits) {
    Frame f;
    f.bits = std::move(bits);
    return f;
  };
  Step one;
  one.sensor_zero_bits = {0.2, 0.6, 0.0, 3.0};
  one.stance = {frame({1, 2, 0, 4}), frame({3, 1, 0, 10})};
  Step two;
  two.sensor_zero_bits = {0.0, 0.4, 0.5, 3.0};
  two.stance = {frame({0, 3, 3, 4})};
  const std::vector<Step> steps{one, two};
  const CellsAtZero counted = loaded_cells_at_zero(steps);
  EXPECT_EQ(counted.loaded, 4u);
  EXPECT_EQ(counted.at_zero, 2u);
  EXPECT_DOUBLE_EQ(counted.pct(), 50.0);
  EXPECT_EQ(loaded_cells_at_zero({}).pct(), 0.0);
}

// Two recordings, worked by hand: weights 1 / se^2 of 100 and 25 give a mean gain of
// (100 x 1 + 25 x 2) / 125 = 1.2 with se 1 / sqrt(125); chi-square 100 x 0.2^2 + 25 x 0.8^2 = 20
// on one degree of freedom, whose upper tail is erfc(sqrt(20 / 2)) = 7.74e-6.
TEST(CreepAgreement, WeighsEachRecordingByItsErrorAndTestsTheSpreadAgainstThem) {
  const std::vector<MeasuredCreep> two{{1.0, 0.1, 3.0, 0.5}, {2.0, 0.2, 3.0, 1.0}};
  const CreepAgreement a = creep_agreement(two);
  EXPECT_EQ(a.recordings, 2u);
  EXPECT_NEAR(a.mean.gain, 1.2, 1e-12);
  EXPECT_NEAR(a.mean.gain_se, 1.0 / std::sqrt(125.0), 1e-12);
  EXPECT_NEAR(a.gain_chi2, 20.0, 1e-9);
  EXPECT_NEAR(a.gain_p, std::erfc(std::sqrt(10.0)), 1e-12);
  EXPECT_NEAR(a.mean.tau_s, 3.0, 1e-12);
  EXPECT_NEAR(a.mean.tau_se_s, 1.0 / std::sqrt(5.0), 1e-12);
  EXPECT_NEAR(a.tau_chi2, 0.0, 1e-12);
  EXPECT_NEAR(a.tau_p, 1.0, 1e-12);
  EXPECT_FALSE(a.agree) << "the gains are 4.5 of their combined errors apart";

  // Three within their errors: chi-square 0.5 + 0 + 0.5 = 1 on two degrees of freedom, whose
  // upper tail is exp(-1 / 2).
  const std::vector<MeasuredCreep> three{{0.29, 0.01 * std::sqrt(2.0), 2.0, 0.1},
                                         {0.30, 0.01, 2.0, 0.1},
                                         {0.31, 0.01 * std::sqrt(2.0), 2.0, 0.1}};
  const CreepAgreement b = creep_agreement(three);
  EXPECT_NEAR(b.mean.gain, 0.30, 1e-12);
  EXPECT_NEAR(b.gain_chi2, 1.0, 1e-9);
  EXPECT_NEAR(b.gain_p, std::exp(-0.5), 1e-9);
  EXPECT_TRUE(b.agree);
  EXPECT_FALSE(creep_agreement(three, 0.7).agree) << "p 0.61 under a min_p of 0.7";
}

TEST(CreepAgreement, RefusesOneRecordingOrOneWithoutAStandardError) {
  const MeasuredCreep one{0.3, 0.01, 2.0, 0.1};
  EXPECT_THROW(creep_agreement(std::vector<MeasuredCreep>{one}), std::invalid_argument);
  MeasuredCreep undetermined = one;
  undetermined.tau_se_s = INFINITY;
  EXPECT_THROW(creep_agreement(std::vector<MeasuredCreep>{one, undetermined}),
               std::invalid_argument);
  undetermined.tau_se_s = 0.0;
  EXPECT_THROW(creep_agreement(std::vector<MeasuredCreep>{one, undetermined}),
               std::invalid_argument);
  EXPECT_THROW(creep_agreement(std::vector<MeasuredCreep>{one, one}, 0.0), std::invalid_argument);
  EXPECT_THROW(creep_agreement(std::vector<MeasuredCreep>{one, one}, 1.5), std::invalid_argument);
  EXPECT_TRUE(creep_agreement(std::vector<MeasuredCreep>{one, one}, 1.0).agree)
      << "two equal recordings: chi-square 0, p 1";
}

}  // namespace
}  // namespace gaitmon
