// The shared vocabulary's text names, which are part of the file formats: every value has the
// documented name and parses back, unknown or mis-spelt text is rejected, and each insole size
// has the session format's sensor count.
#include "gaitmon/types.hpp"

#include <gtest/gtest.h>

#include <array>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <string_view>

namespace gaitmon {
namespace {

TEST(Types, FootNames) {
  EXPECT_EQ(foot_name(Foot::Left), "L");
  EXPECT_EQ(foot_name(Foot::Right), "R");
}

TEST(Types, EveryRegionHasItsDocumentedNameAndParsesBack) {
  const std::array<std::string_view, kRegionCount> names{
      "heel",   "midfoot_posterior", "midfoot_anterior", "met1_2", "met3_5", "toe1", "toe2",
      "toes3_5"};
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    const Region region = kRegions[i];
    EXPECT_EQ(index_of(region), i) << "kRegions is in enum order";
    EXPECT_EQ(region_name(region), names[i]);
    EXPECT_EQ(parse_region(names[i]), region) << names[i];
  }
}

TEST(Types, EveryInsoleSizeHasItsDocumentedNameAndParsesBack) {
  const std::array<std::string_view, kInsoleSizeCount> names{"35-36", "37-38", "39-40",
                                                             "41-42", "43-44", "45-46"};
  for (std::size_t i = 0; i < kInsoleSizeCount; ++i) {
    const InsoleSize size = kInsoleSizes[i];
    EXPECT_EQ(index_of(size), i) << "kInsoleSizes is in enum order";
    EXPECT_EQ(insole_size_name(size), names[i]);
    EXPECT_EQ(parse_insole_size(names[i]), size) << names[i];
  }
}

// Names are matched exactly: no case folding, trimming, prefixes or other separators.
TEST(Types, UnknownTextIsRejected) {
  for (std::string_view text :
       {"", "Heel", "HEEL", " heel", "heel ", "hee", "heels", "toe3", "toes", "met1-2", "L"}) {
    EXPECT_EQ(parse_region(text), std::nullopt) << '"' << text << '"';
  }
  for (std::string_view text :
       {"", "35", "35_36", "35-37", "33-34", "47-48", " 37-38", "37-38 ", "3738", "heel"}) {
    EXPECT_EQ(parse_insole_size(text), std::nullopt) << '"' << text << '"';
  }
}

// A name embedded in a longer buffer is parsed from the view alone, not up to a terminator.
TEST(Types, ParsesAViewIntoALongerString) {
  const std::string buffer = "toe1,37-38";
  EXPECT_EQ(parse_region(std::string_view(buffer).substr(0, 4)), Region::Toe1);
  EXPECT_EQ(parse_insole_size(std::string_view(buffer).substr(5)), InsoleSize::S37_38);
}

TEST(Types, ToesAreExactlyTheThreeToeRegions) {
  std::set<Region> toes;
  for (Region region : kRegions) {
    if (is_toe(region)) toes.insert(region);
  }
  EXPECT_EQ(toes, (std::set<Region>{Region::Toe1, Region::Toe2, Region::Toes3_5}));
}

TEST(Types, SessionSensorCountMatchesTheFormat) {
  EXPECT_EQ(session_sensor_count(InsoleSize::S35_36), 93u);
  EXPECT_EQ(session_sensor_count(InsoleSize::S37_38), 107u);
  EXPECT_EQ(session_sensor_count(InsoleSize::S39_40), 116u);
  EXPECT_EQ(session_sensor_count(InsoleSize::S41_42), 129u);
  EXPECT_EQ(session_sensor_count(InsoleSize::S43_44), 151u);
  EXPECT_EQ(session_sensor_count(InsoleSize::S45_46), 161u);
}

// A size byte from outside (a corrupt header cast to the enum) must not yield a count.
TEST(Types, SessionSensorCountRefusesAnInvalidSize) {
  try {
    session_sensor_count(static_cast<InsoleSize>(kInsoleSizeCount));
    ADD_FAILURE() << "an invalid size has a count";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("invalid insole size"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace gaitmon
