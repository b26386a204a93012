// Vocabulary shared by every unit: feet, anatomical regions and insole sizes, with their text
// names.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>

namespace gaitmon {

enum class Foot : std::uint8_t { Left, Right };
inline constexpr std::array<Foot, 2> kFeet{Foot::Left, Foot::Right};

/// "L" or "R", as in session files and outputs.
std::string_view foot_name(Foot foot);

/// The seed's eight anatomical regions, posterior to anterior then lateral to medial toes.
enum class Region : std::uint8_t {
  Heel,
  MidfootPosterior,
  MidfootAnterior,
  Met1_2,
  Met3_5,
  Toe1,
  Toe2,
  Toes3_5,
};
inline constexpr std::size_t kRegionCount = 8;
inline constexpr std::array<Region, kRegionCount> kRegions{
    Region::Heel,   Region::MidfootPosterior, Region::MidfootAnterior,
    Region::Met1_2, Region::Met3_5,           Region::Toe1,
    Region::Toe2,   Region::Toes3_5};

/// heel, midfoot_posterior, midfoot_anterior, met1_2, met3_5, toe1, toe2, toes3_5.
std::string_view region_name(Region region);
std::optional<Region> parse_region(std::string_view text);
constexpr std::size_t index_of(Region region) {
  return static_cast<std::size_t>(region);
}
constexpr bool is_toe(Region region) {
  return region == Region::Toe1 || region == Region::Toe2 || region == Region::Toes3_5;
}

/// The frame rates per foot (Hz) that sessions and the config may give. The step detector's
/// windows are whole frames: below 10 Hz a swing is a frame or two and its 5-frame windows
/// cannot fit.
inline constexpr double kMinSampleRateHz = 10.0;
inline constexpr double kMaxSampleRateHz = 10000.0;

/// The six Medilogic insole sizes (EU shoe sizes).
enum class InsoleSize : std::uint8_t { S35_36, S37_38, S39_40, S41_42, S43_44, S45_46 };
inline constexpr std::size_t kInsoleSizeCount = 6;
inline constexpr std::array<InsoleSize, kInsoleSizeCount> kInsoleSizes{
    InsoleSize::S35_36, InsoleSize::S37_38, InsoleSize::S39_40,
    InsoleSize::S41_42, InsoleSize::S43_44, InsoleSize::S45_46};

/// "35-36" ... "45-46".
std::string_view insole_size_name(InsoleSize size);
std::optional<InsoleSize> parse_insole_size(std::string_view text);
constexpr std::size_t index_of(InsoleSize size) {
  return static_cast<std::size_t>(size);
}

/// The number of sensors of each insole size as sessions and devices carry them (93 ... 161;
/// Appendix B's count, shared/docs/session-format.md).
std::size_t session_sensor_count(InsoleSize size);

}  // namespace gaitmon
