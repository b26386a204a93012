// The sensor grid of one insole size: each sensor's row, region and position on the foot.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "gaitmon/config.hpp"
#include "gaitmon/types.hpp"

namespace gaitmon {

/// One sensor. Positions are the cell centre in the insole frame: x lateral -> medial with 0 on
/// the midline, y posterior -> anterior with 0 at the most posterior row. `x_mm, y_mm` use the
/// configured pitch; `grid_x_mm, grid_y_mm` place the same cell as if the cells were contiguous
/// (pitch = sensor size), the frame in which contact areas and ellipses are measured, so that a
/// cell always stands for its sensing area whatever the pitch.
struct Sensor {
  std::size_t index = 0;  ///< 0-based; session column s<index+1>
  int row = 0;            ///< 1-based, 1 = most anterior
  int number_in_row = 0;  ///< 1-based, lateral to medial
  Region region = Region::Heel;
  double x_mm = 0.0;
  double y_mm = 0.0;
  double grid_x_mm = 0.0;
  double grid_y_mm = 0.0;
};

/// A sensor next to another across an edge of their cells in the grid frame.
struct Neighbour {
  std::size_t sensor = 0;
  /// The share of the edge the two cells have in common: 1 for a whole edge; less between rows
  /// of different lengths, whose cells sit half a cell apart.
  double shared_edge = 0.0;
};

/// Invariant: sensors are numbered row by row from the most anterior row, lateral to medial,
/// every sensor belongs to exactly one region, and every region has at least one sensor.
class InsoleLayout {
 public:
  /// Builds the layout; throws std::invalid_argument if the spec breaks the invariant (the
  /// config loader validates first and reports the file and key).
  InsoleLayout(const InsoleSpec& spec, const SensorGeometry& geometry);

  InsoleSize size() const { return size_; }
  const SensorGeometry& geometry() const { return geometry_; }
  double adaptive_threshold_pct() const { return threshold_pct_; }

  std::size_t sensor_count() const { return sensors_.size(); }
  std::span<const Sensor> sensors() const { return sensors_; }
  const Sensor& sensor(std::size_t index) const { return sensors_.at(index); }

  int row_count() const { return static_cast<int>(row_lengths_.size()); }
  int row_length(int row) const { return row_lengths_.at(static_cast<std::size_t>(row - 1)); }
  /// The most posterior row (the heel's outermost), used by the isolated-sensor exception.
  int outermost_heel_row() const { return row_count(); }

  /// Indices of the sensors of one region, in sensor order.
  std::span<const std::size_t> region_sensors(Region region) const {
    return region_sensors_[index_of(region)];
  }

  /// The sensors whose cells share an edge with this one's, in sensor order.
  std::span<const Neighbour> neighbours(std::size_t sensor) const { return neighbours_.at(sensor); }

  /// Width over height of the bounding box of a region's cells in the grid frame, cell edges
  /// included: the shape a footprint grows into where its loads cannot give its aspect.
  double region_box_aspect(Region region) const;

 private:
  InsoleSize size_;
  SensorGeometry geometry_;
  double threshold_pct_;
  std::vector<int> row_lengths_;
  std::vector<Sensor> sensors_;
  std::array<std::vector<std::size_t>, kRegionCount> region_sensors_;
  std::vector<std::vector<Neighbour>> neighbours_;
};

}  // namespace gaitmon
