// Builds an insole's sensor list from its region spans and places each cell on the foot.
#include "gaitmon/insole.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>

namespace gaitmon {
namespace {

[[noreturn]] void invalid(InsoleSize size, const std::string& reason) {
  throw std::invalid_argument(fmt::format("insole layout {}: {}", insole_size_name(size), reason));
}

void check_geometry(InsoleSize size, const SensorGeometry& g) {
  const bool finite = std::isfinite(g.width_mm) && std::isfinite(g.height_mm) &&
                      std::isfinite(g.pitch_x_mm) && std::isfinite(g.pitch_y_mm);
  if (!finite || !(g.width_mm > 0.0) || !(g.height_mm > 0.0)) {
    invalid(size, "sensor width and height must be finite and > 0");
  }
  if (g.pitch_x_mm < g.width_mm || g.pitch_y_mm < g.height_mm) {
    invalid(size, "the pitch must be at least the sensor size on each axis (cells cannot overlap)");
  }
}

// Offset, in cells, of sensor 1 of a row of `length` so that x = (number - offset) * pitch.
double first_offset(RowAlignment alignment, int length, int widest) {
  switch (alignment) {
    case RowAlignment::Lateral:
      return (widest + 1) / 2.0;
    case RowAlignment::Medial:
      return length + 1 - (widest + 1) / 2.0;
    case RowAlignment::Centred:
      break;
  }
  return (length + 1) / 2.0;
}

}  // namespace

InsoleLayout::InsoleLayout(const InsoleSpec& spec, const SensorGeometry& geometry)
    : size_(spec.size), geometry_(geometry), threshold_pct_(spec.adaptive_threshold_pct) {
  check_geometry(size_, geometry_);
  if (!(threshold_pct_ > 0.0 && threshold_pct_ <= 100.0)) {
    invalid(size_, "adaptive_threshold_pct must be in (0, 100]");
  }

  // owner[row - 1][number - 1]: the region of each cell listed by some span.
  std::vector<std::vector<std::optional<Region>>> owner;
  for (Region region : kRegions) {
    const auto& spans = spec.regions[index_of(region)];
    if (spans.empty()) invalid(size_, fmt::format("region {} has no sensors", region_name(region)));
    for (const RowSpan& span : spans) {
      if (span.row < 1 || span.row > kMaxInsoleRows || span.first < 1 || span.first > span.last ||
          span.last > kMaxSensorsPerRow) {
        invalid(size_, fmt::format("bad span {}:{}-{} in {}", span.row, span.first, span.last,
                                   region_name(region)));
      }
      const auto row = static_cast<std::size_t>(span.row - 1);
      if (owner.size() <= row) owner.resize(row + 1);
      if (owner[row].size() < static_cast<std::size_t>(span.last)) {
        owner[row].resize(static_cast<std::size_t>(span.last));
      }
      for (int number = span.first; number <= span.last; ++number) {
        auto& cell = owner[row][static_cast<std::size_t>(number - 1)];
        if (cell) {
          invalid(size_, fmt::format("row {} sensor {} is in both {} and {}", span.row, number,
                                     region_name(*cell), region_name(region)));
        }
        cell = region;
      }
    }
  }

  for (std::size_t r = 0; r < owner.size(); ++r) {
    if (owner[r].empty()) invalid(size_, fmt::format("row {} has no sensors", r + 1));
    for (std::size_t j = 0; j < owner[r].size(); ++j) {
      if (!owner[r][j])
        invalid(size_, fmt::format("row {} sensor {} is in no region", r + 1, j + 1));
    }
    row_lengths_.push_back(static_cast<int>(owner[r].size()));
  }

  const int widest = *std::max_element(row_lengths_.begin(), row_lengths_.end());
  const int rows = row_count();
  for (int row = 1; row <= rows; ++row) {
    const int length = row_length(row);
    const double offset = first_offset(geometry_.alignment, length, widest);
    const double rows_from_back = rows - row;
    for (int number = 1; number <= length; ++number) {
      Sensor s;
      s.index = sensors_.size();
      s.row = row;
      s.number_in_row = number;
      s.region = *owner[static_cast<std::size_t>(row - 1)][static_cast<std::size_t>(number - 1)];
      s.x_mm = (number - offset) * geometry_.pitch_x_mm;
      s.y_mm = rows_from_back * geometry_.pitch_y_mm;
      s.grid_x_mm = (number - offset) * geometry_.width_mm;
      s.grid_y_mm = rows_from_back * geometry_.height_mm;
      region_sensors_[index_of(s.region)].push_back(s.index);
      sensors_.push_back(s);
    }
  }

  // In the grid frame the cells tile the insole: two cells in one row touch along their height,
  // and two in rows next to each other along the width they overlap by.
  const double w = geometry_.width_mm;
  neighbours_.resize(sensors_.size());
  for (const Sensor& a : sensors_) {
    for (const Sensor& b : sensors_) {
      const double dx = std::abs(a.grid_x_mm - b.grid_x_mm);
      double shared = 0.0;
      if (a.row == b.row) {
        shared = std::abs(dx - w) < 1e-6 * w ? 1.0 : 0.0;
      } else if (std::abs(a.row - b.row) == 1) {
        shared = std::max(0.0, 1.0 - dx / w);
      }
      if (shared > 1e-9) neighbours_[a.index].push_back({b.index, shared});
    }
  }
}

double InsoleLayout::region_box_aspect(Region region) const {
  const auto& cells = region_sensors_[index_of(region)];
  const auto [x_lo, x_hi] = std::minmax_element(cells.begin(), cells.end(), [&](auto a, auto b) {
    return sensors_[a].grid_x_mm < sensors_[b].grid_x_mm;
  });
  const auto [y_lo, y_hi] = std::minmax_element(cells.begin(), cells.end(), [&](auto a, auto b) {
    return sensors_[a].grid_y_mm < sensors_[b].grid_y_mm;
  });
  return (sensors_[*x_hi].grid_x_mm - sensors_[*x_lo].grid_x_mm + geometry_.width_mm) /
         (sensors_[*y_hi].grid_y_mm - sensors_[*y_lo].grid_y_mm + geometry_.height_mm);
}

}  // namespace gaitmon
