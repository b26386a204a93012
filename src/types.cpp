// Text names of the shared vocabulary; the names are part of the file formats.
#include "gaitmon/types.hpp"

#include <stdexcept>

namespace gaitmon {
namespace {
constexpr std::array<std::string_view, kRegionCount> kRegionNames{
    "heel", "midfoot_posterior", "midfoot_anterior", "met1_2", "met3_5", "toe1", "toe2", "toes3_5"};
constexpr std::array<std::string_view, kInsoleSizeCount> kSizeNames{"35-36", "37-38", "39-40",
                                                                    "41-42", "43-44", "45-46"};
}  // namespace

std::string_view foot_name(Foot foot) {
  return foot == Foot::Left ? "L" : "R";
}

std::string_view region_name(Region region) {
  return kRegionNames[index_of(region)];
}

std::optional<Region> parse_region(std::string_view text) {
  for (Region r : kRegions) {
    if (kRegionNames[index_of(r)] == text) return r;
  }
  return std::nullopt;
}

std::string_view insole_size_name(InsoleSize size) {
  return kSizeNames[index_of(size)];
}

std::optional<InsoleSize> parse_insole_size(std::string_view text) {
  for (InsoleSize s : kInsoleSizes) {
    if (kSizeNames[index_of(s)] == text) return s;
  }
  return std::nullopt;
}

std::size_t session_sensor_count(InsoleSize size) {
  switch (size) {
    case InsoleSize::S35_36:
      return 93;
    case InsoleSize::S37_38:
      return 107;
    case InsoleSize::S39_40:
      return 116;
    case InsoleSize::S41_42:
      return 129;
    case InsoleSize::S43_44:
      return 151;
    case InsoleSize::S45_46:
      return 161;
  }
  throw std::invalid_argument("session_sensor_count: invalid insole size");
}

}  // namespace gaitmon
