// InsoleLayout: sensor order, regions and positions on hand-made specs worked out on paper.
#include "gaitmon/insole.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <stdexcept>
#include <vector>

namespace gaitmon {
namespace {

using ::testing::Contains;
using ::testing::ElementsAre;

struct Xy {
  double x;
  double y;
};

// Rows of 3, 2 and 3 sensors (8 in all), one sensor per region:
//   row 1: toes3_5 toe2 toe1
//   row 2: met3_5 met1_2
//   row 3: midfoot_anterior midfoot_posterior heel
InsoleSpec spec_3_2_3() {
  InsoleSpec spec;
  spec.size = InsoleSize::S37_38;
  spec.adaptive_threshold_pct = 0.2;
  spec.regions[index_of(Region::Toes3_5)] = {{1, 1, 1}};
  spec.regions[index_of(Region::Toe2)] = {{1, 2, 2}};
  spec.regions[index_of(Region::Toe1)] = {{1, 3, 3}};
  spec.regions[index_of(Region::Met3_5)] = {{2, 1, 1}};
  spec.regions[index_of(Region::Met1_2)] = {{2, 2, 2}};
  spec.regions[index_of(Region::MidfootAnterior)] = {{3, 1, 1}};
  spec.regions[index_of(Region::MidfootPosterior)] = {{3, 2, 2}};
  spec.regions[index_of(Region::Heel)] = {{3, 3, 3}};
  return spec;
}

// Rows of 2, 4 and 3 sensors (9 in all): the widest row is in the middle, so lateral and
// medial alignment move the outer rows differently.
//   row 1: toes3_5 toe1
//   row 2: toe2 met3_5 midfoot_posterior met1_2
//   row 3: midfoot_anterior heel heel
InsoleSpec spec_2_4_3() {
  InsoleSpec spec;
  spec.size = InsoleSize::S35_36;
  spec.adaptive_threshold_pct = 0.1;
  spec.regions[index_of(Region::Toes3_5)] = {{1, 1, 1}};
  spec.regions[index_of(Region::Toe1)] = {{1, 2, 2}};
  spec.regions[index_of(Region::Toe2)] = {{2, 1, 1}};
  spec.regions[index_of(Region::Met3_5)] = {{2, 2, 2}};
  spec.regions[index_of(Region::MidfootPosterior)] = {{2, 3, 3}};
  spec.regions[index_of(Region::Met1_2)] = {{2, 4, 4}};
  spec.regions[index_of(Region::MidfootAnterior)] = {{3, 1, 1}};
  spec.regions[index_of(Region::Heel)] = {{3, 2, 3}};
  return spec;
}

SensorGeometry geometry(RowAlignment alignment, double pitch_x_mm = 7.5, double pitch_y_mm = 15.0) {
  SensorGeometry g;
  g.width_mm = 7.5;
  g.height_mm = 15.0;
  g.pitch_x_mm = pitch_x_mm;
  g.pitch_y_mm = pitch_y_mm;
  g.alignment = alignment;
  return g;
}

void expect_positions(const InsoleLayout& layout, const std::vector<Xy>& xy,
                      const std::vector<Xy>& grid) {
  ASSERT_EQ(layout.sensor_count(), xy.size());
  ASSERT_EQ(layout.sensor_count(), grid.size());
  for (std::size_t i = 0; i < xy.size(); ++i) {
    SCOPED_TRACE(i);
    const Sensor& s = layout.sensor(i);
    EXPECT_DOUBLE_EQ(s.x_mm, xy[i].x);
    EXPECT_DOUBLE_EQ(s.y_mm, xy[i].y);
    EXPECT_DOUBLE_EQ(s.grid_x_mm, grid[i].x);
    EXPECT_DOUBLE_EQ(s.grid_y_mm, grid[i].y);
  }
}

TEST(InsoleLayout, NumbersSensorsRowByRowLateralToMedial) {
  const InsoleLayout layout(spec_3_2_3(), geometry(RowAlignment::Centred));
  EXPECT_EQ(layout.size(), InsoleSize::S37_38);
  EXPECT_DOUBLE_EQ(layout.adaptive_threshold_pct(), 0.2);
  EXPECT_EQ(layout.sensor_count(), 8u);
  EXPECT_EQ(layout.row_count(), 3);
  EXPECT_EQ(layout.row_length(1), 3);
  EXPECT_EQ(layout.row_length(2), 2);
  EXPECT_EQ(layout.row_length(3), 3);
  const std::vector<int> rows{1, 1, 1, 2, 2, 3, 3, 3};
  const std::vector<int> numbers{1, 2, 3, 1, 2, 1, 2, 3};
  const std::vector<Region> regions{
      Region::Toes3_5,          Region::Toe2,   Region::Toe1,
      Region::Met3_5,           Region::Met1_2, Region::MidfootAnterior,
      Region::MidfootPosterior, Region::Heel};
  for (std::size_t i = 0; i < 8; ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(layout.sensor(i).index, i);
    EXPECT_EQ(layout.sensor(i).row, rows[i]);
    EXPECT_EQ(layout.sensor(i).number_in_row, numbers[i]);
    EXPECT_EQ(layout.sensor(i).region, regions[i]);
  }
  EXPECT_THROW(static_cast<void>(layout.sensor(8)), std::out_of_range);
}

TEST(InsoleLayout, CentredRowsSitOnTheMidline) {
  // Row 3 is the most posterior (y = 0); rows 2 and 1 are one and two pitches anterior.
  // A row of 3 has its middle sensor on x = 0; a row of 2 straddles it by half a pitch.
  const InsoleLayout layout(spec_3_2_3(), geometry(RowAlignment::Centred));
  const std::vector<Xy> xy{{-7.5, 30}, {0, 30},   {7.5, 30}, {-3.75, 15},
                           {3.75, 15}, {-7.5, 0}, {0, 0},    {7.5, 0}};
  expect_positions(layout, xy, xy);
}

TEST(InsoleLayout, LateralAlignmentLinesUpFirstSensors) {
  const InsoleLayout layout(spec_3_2_3(), geometry(RowAlignment::Lateral));
  const std::vector<Xy> xy{{-7.5, 30}, {0, 30},   {7.5, 30}, {-7.5, 15},
                           {0, 15},    {-7.5, 0}, {0, 0},    {7.5, 0}};
  expect_positions(layout, xy, xy);
}

TEST(InsoleLayout, MedialAlignmentLinesUpLastSensors) {
  const InsoleLayout layout(spec_3_2_3(), geometry(RowAlignment::Medial));
  const std::vector<Xy> xy{{-7.5, 30}, {0, 30},   {7.5, 30}, {0, 15},
                           {7.5, 15},  {-7.5, 0}, {0, 0},    {7.5, 0}};
  expect_positions(layout, xy, xy);
}

TEST(InsoleLayout, LateralAndMedialCentreTheWidestRow) {
  // The widest row (row 2, 4 sensors) sits at -11.25, -3.75, 3.75, 11.25 in both alignments.
  // Lateral: every row starts at -11.25. Medial: every row ends at 11.25.
  const std::vector<Xy> lateral{{-11.25, 30}, {-3.75, 30}, {-11.25, 15}, {-3.75, 15}, {3.75, 15},
                                {11.25, 15},  {-11.25, 0}, {-3.75, 0},   {3.75, 0}};
  expect_positions(InsoleLayout(spec_2_4_3(), geometry(RowAlignment::Lateral)), lateral, lateral);
  const std::vector<Xy> medial{{3.75, 30},  {11.25, 30}, {-11.25, 15}, {-3.75, 15}, {3.75, 15},
                               {11.25, 15}, {-3.75, 0},  {3.75, 0},    {11.25, 0}};
  expect_positions(InsoleLayout(spec_2_4_3(), geometry(RowAlignment::Medial)), medial, medial);
  // Centred: row 1 at +-3.75, row 3 at -7.5, 0, 7.5.
  const std::vector<Xy> centred{{-3.75, 30}, {3.75, 30}, {-11.25, 15}, {-3.75, 15}, {3.75, 15},
                                {11.25, 15}, {-7.5, 0},  {0, 0},       {7.5, 0}};
  expect_positions(InsoleLayout(spec_2_4_3(), geometry(RowAlignment::Centred)), centred, centred);
}

TEST(InsoleLayout, PitchSpreadsCellsButGridKeepsThemContiguous) {
  // Pitch 10 x 20 mm with 7.5 x 15 mm cells: x, y scale by the pitch, grid_x, grid_y by the size.
  const InsoleLayout centred(spec_3_2_3(), geometry(RowAlignment::Centred, 10.0, 20.0));
  expect_positions(
      centred, {{-10, 40}, {0, 40}, {10, 40}, {-5, 20}, {5, 20}, {-10, 0}, {0, 0}, {10, 0}},
      {{-7.5, 30}, {0, 30}, {7.5, 30}, {-3.75, 15}, {3.75, 15}, {-7.5, 0}, {0, 0}, {7.5, 0}});
  const InsoleLayout medial(spec_3_2_3(), geometry(RowAlignment::Medial, 10.0, 20.0));
  expect_positions(
      medial, {{-10, 40}, {0, 40}, {10, 40}, {0, 20}, {10, 20}, {-10, 0}, {0, 0}, {10, 0}},
      {{-7.5, 30}, {0, 30}, {7.5, 30}, {0, 15}, {7.5, 15}, {-7.5, 0}, {0, 0}, {7.5, 0}});
}

TEST(InsoleLayout, SensorAreaDoesNotDependOnPitch) {
  const InsoleLayout tight(spec_3_2_3(), geometry(RowAlignment::Centred));
  const InsoleLayout spread(spec_3_2_3(), geometry(RowAlignment::Centred, 12.0, 25.0));
  // 7.5 mm x 15 mm = 112.5 mm^2 = 1.125 cm^2.
  EXPECT_DOUBLE_EQ(tight.geometry().area_mm2(), 112.5);
  EXPECT_DOUBLE_EQ(spread.geometry().area_mm2(), 112.5);
}

TEST(InsoleLayout, RegionSensorsAndOutermostHeelRow) {
  const InsoleLayout small(spec_3_2_3(), geometry(RowAlignment::Centred));
  EXPECT_THAT(small.region_sensors(Region::Heel), ElementsAre(7u));
  EXPECT_THAT(small.region_sensors(Region::Toe1), ElementsAre(2u));
  EXPECT_THAT(small.region_sensors(Region::Met3_5), ElementsAre(3u));
  EXPECT_EQ(small.outermost_heel_row(), 3);

  const InsoleLayout wide(spec_2_4_3(), geometry(RowAlignment::Centred));
  EXPECT_THAT(wide.region_sensors(Region::Heel), ElementsAre(7u, 8u));
  EXPECT_THAT(wide.region_sensors(Region::MidfootPosterior), ElementsAre(4u));
  EXPECT_THAT(wide.region_sensors(Region::Met1_2), ElementsAre(5u));
  EXPECT_EQ(wide.outermost_heel_row(), 3);
}

// One cell is 7.5 x 15 mm; two side by side in a row are 15 x 15 mm, whatever the pitch.
TEST(InsoleLayout, RegionBoxAspectSpansTheCellsEdgeToEdge) {
  const InsoleLayout wide(spec_2_4_3(), geometry(RowAlignment::Centred, 9.0, 20.0));
  EXPECT_DOUBLE_EQ(wide.region_box_aspect(Region::Heel), 1.0);
  EXPECT_DOUBLE_EQ(wide.region_box_aspect(Region::Met1_2), 0.5);
}

std::vector<std::pair<std::size_t, double>> neighbours_of(const InsoleLayout& layout,
                                                          std::size_t sensor) {
  std::vector<std::pair<std::size_t, double>> out;
  for (const Neighbour& n : layout.neighbours(sensor)) out.emplace_back(n.sensor, n.shared_edge);
  return out;
}

TEST(InsoleLayout, NeighboursShareAWholeEdgeInARowAndTheirOverlapAcrossRows) {
  // Centred 3-2-3: the row of two sits half a cell off the rows of three, so each of its cells
  // overlaps two cells above and two below by half a width; a corner touch is no neighbour.
  using P = std::pair<std::size_t, double>;
  const InsoleLayout centred(spec_3_2_3(), geometry(RowAlignment::Centred, 9.0, 20.0));
  EXPECT_THAT(neighbours_of(centred, 0), ElementsAre(P{1, 1.0}, P{3, 0.5}));
  EXPECT_THAT(neighbours_of(centred, 1), ElementsAre(P{0, 1.0}, P{2, 1.0}, P{3, 0.5}, P{4, 0.5}));
  EXPECT_THAT(neighbours_of(centred, 3),
              ElementsAre(P{0, 0.5}, P{1, 0.5}, P{4, 1.0}, P{5, 0.5}, P{6, 0.5}));
  // Lateral alignment lines the rows up: whole edges only.
  const InsoleLayout lateral(spec_3_2_3(), geometry(RowAlignment::Lateral, 9.0, 20.0));
  EXPECT_THAT(neighbours_of(lateral, 3), ElementsAre(P{0, 1.0}, P{4, 1.0}, P{5, 1.0}));
  EXPECT_THAT(neighbours_of(lateral, 2), ElementsAre(P{1, 1.0}));
  for (std::size_t s = 0; s < centred.sensor_count(); ++s) {
    for (const Neighbour& n : centred.neighbours(s)) {
      EXPECT_THAT(neighbours_of(centred, n.sensor), Contains(P{s, n.shared_edge}));
    }
  }
}

TEST(InsoleLayout, RegionSensorsComeInSensorOrderWhateverTheSpanOrder) {
  InsoleSpec spec = spec_2_4_3();
  spec.regions[index_of(Region::Heel)] = {{3, 3, 3}, {3, 2, 2}};
  const InsoleLayout layout(spec, geometry(RowAlignment::Centred));
  EXPECT_THAT(layout.region_sensors(Region::Heel), ElementsAre(7u, 8u));
  EXPECT_EQ(layout.sensor(7).region, Region::Heel);
  EXPECT_EQ(layout.sensor(8).region, Region::Heel);
}

TEST(InsoleLayout, RefusesBrokenSpecs) {
  const SensorGeometry g = geometry(RowAlignment::Centred);
  {
    InsoleSpec spec = spec_3_2_3();
    spec.regions[index_of(Region::Toe2)].clear();  // toe1 takes its sensor: toe2 is empty
    spec.regions[index_of(Region::Toe1)] = {{1, 2, 3}};
    EXPECT_THROW(InsoleLayout(spec, g), std::invalid_argument);
  }
  {
    InsoleSpec spec = spec_3_2_3();
    spec.regions[index_of(Region::Toe2)] = {{1, 2, 3}};  // row 1 sensor 3 also in toe1
    EXPECT_THROW(InsoleLayout(spec, g), std::invalid_argument);
  }
  {
    InsoleSpec spec = spec_3_2_3();
    spec.regions[index_of(Region::Toe2)] = {{1, 4, 4}};  // row 1 sensor 2 in no region
    EXPECT_THROW(InsoleLayout(spec, g), std::invalid_argument);
  }
  {
    InsoleSpec spec = spec_3_2_3();
    spec.regions[index_of(Region::Heel)] = {{5, 1, 1}};  // row 4 empty between 3 and 5
    spec.regions[index_of(Region::MidfootPosterior)] = {{3, 2, 3}};
    EXPECT_THROW(InsoleLayout(spec, g), std::invalid_argument);
  }
  {
    InsoleSpec spec = spec_3_2_3();
    spec.regions[index_of(Region::Heel)] = {{3, 3, 2}};  // first after last
    EXPECT_THROW(InsoleLayout(spec, g), std::invalid_argument);
  }
  {
    InsoleSpec spec = spec_3_2_3();
    spec.regions[index_of(Region::Heel)] = {{0, 3, 3}};  // row 0
    EXPECT_THROW(InsoleLayout(spec, g), std::invalid_argument);
  }
  {
    InsoleSpec spec = spec_3_2_3();
    spec.regions[index_of(Region::Heel)] = {{3, 3, 3}, {3, 4, 100000}};  // absurd sensor number
    EXPECT_THROW(InsoleLayout(spec, g), std::invalid_argument);
  }
  {
    InsoleSpec spec = spec_3_2_3();
    spec.adaptive_threshold_pct = 0.0;
    EXPECT_THROW(InsoleLayout(spec, g), std::invalid_argument);
  }
  EXPECT_THROW(InsoleLayout(spec_3_2_3(), geometry(RowAlignment::Centred, 7.0, 15.0)),
               std::invalid_argument);  // cells would overlap lateral-medially
  EXPECT_THROW(InsoleLayout(spec_3_2_3(), geometry(RowAlignment::Centred, 7.5, 14.0)),
               std::invalid_argument);
  SensorGeometry zero_width = g;
  zero_width.width_mm = 0.0;
  EXPECT_THROW(InsoleLayout(spec_3_2_3(), zero_width), std::invalid_argument);
}

}  // namespace
}  // namespace gaitmon
