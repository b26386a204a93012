// CreepCorrection: the exact inverse of the simulator's creep, frame by frame.
#include "gaitmon/creep.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <stdexcept>
#include <vector>

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

}  // namespace
}  // namespace gaitmon
