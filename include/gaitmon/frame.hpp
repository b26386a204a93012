// One foot's readings at one time: what a session file holds per row and the segmenter consumes,
// whether they came from a file, a replay or a live insole.
#pragma once

#include <cstdint>
#include <vector>

#include "gaitmon/types.hpp"

namespace gaitmon {

/// One frame of one foot: raw readings 0..255, sensor i at bits[i].
struct Frame {
  double t_s = 0.0;
  Foot foot = Foot::Left;
  std::vector<std::uint8_t> bits;
};

}  // namespace gaitmon
