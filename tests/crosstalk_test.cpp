// CrosstalkCorrection undoes the mixing of each cell's reading into its edge neighbours'.
#include "gaitmon/crosstalk.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <vector>

#include "test_support.hpp"

namespace gaitmon {
namespace {

const InsoleLayout& layout() {
  static const Config config = load_config(test::source_dir() / "config" / "gaitmon.toml");
  static const InsoleLayout l(config.insole(InsoleSize::S41_42), config.sensor);
  return l;
}

// Readings b mixed by hand, r_i = b_i + k sum_j e_ij b_j, at the largest coupling allowed too.
TEST(CrosstalkCorrection, GivesBackTheReadingsBeforeTheyWereMixed) {
  const InsoleLayout& l = layout();
  std::vector<double> own(l.sensor_count());
  for (std::size_t c = 0; c < own.size(); ++c) {
    own[c] = 100.0 * std::pow(std::sin(0.37 * static_cast<double>(c)), 2);
  }
  for (const double k : {0.0, 0.03, 0.15, CrosstalkCorrection::kMaxCoupling}) {
    SCOPED_TRACE(k);
    std::vector<double> readings = own;
    for (std::size_t c = 0; c < own.size(); ++c) {
      for (const Neighbour& n : l.neighbours(c)) readings[c] += k * n.shared_edge * own[n.sensor];
    }
    const CrosstalkCorrection correction(l, k);
    EXPECT_EQ(correction.coupling(), k);
    correction.undo(readings);
    for (std::size_t c = 0; c < own.size(); ++c) EXPECT_NEAR(readings[c], own[c], 1e-9) << c;
  }
}

TEST(CrosstalkCorrection, RefusesACouplingOutsideItsRangeAndAFrameOfAnotherSize) {
  EXPECT_THROW(CrosstalkCorrection(layout(), -0.01), std::invalid_argument);
  EXPECT_THROW(CrosstalkCorrection(layout(), 0.25), std::invalid_argument);
  EXPECT_THROW(CrosstalkCorrection(layout(), std::nan("")), std::invalid_argument);
  const CrosstalkCorrection correction(layout(), 0.05);
  std::vector<double> short_frame(layout().sensor_count() - 1, 1.0);
  EXPECT_THROW(correction.undo(short_frame), std::invalid_argument);
}

}  // namespace
}  // namespace gaitmon
