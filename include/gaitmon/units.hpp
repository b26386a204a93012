// Small named types for physical quantities at API boundaries; the member name carries the unit.
#pragma once

namespace gaitmon {

struct Seconds {
  double s = 0.0;
};
struct Hertz {
  double hz = 0.0;
};
struct Newtons {
  double n = 0.0;
};
struct Millimetres {
  double mm = 0.0;
};
struct SquareMillimetres {
  double mm2 = 0.0;
};
struct Kilograms {
  double kg = 0.0;
};

inline constexpr double kStandardGravity_m_per_s2 = 9.80665;

}  // namespace gaitmon
