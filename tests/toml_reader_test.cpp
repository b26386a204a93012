// The TOML reading the config and the calibration designs share: every error names the file, the
// key as a dotted path (quoted where it is not a bare key) and the line, and a key nobody read is
// refused.
#include "src/toml_reader.hpp"

#include <gtest/gtest.h>

#include <string>
#include <string_view>

#include "test_support.hpp"

namespace gaitmon::detail {
namespace {

toml::table parsed(std::string_view text) {
  return toml::parse(text, std::string_view("f.toml"));
}

// The ConfigError `f` throws, as "key: reason"; empty when it throws none.
template <typename F>
std::string refusal(F f) {
  try {
    f();
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.file(), "f.toml");
    return e.key() + ": " + e.reason();
  }
  return {};
}

TEST(TomlReader, NamesTheKeyAsADottedPathQuotedWhereItIsNotBare) {
  EXPECT_EQ(key_text("heel"), "heel");
  EXPECT_EQ(key_text("37-38"), "\"37-38\"");
  EXPECT_EQ(child_path("", "sizes"), "sizes");
  EXPECT_EQ(child_path("sizes", "37-38"), "sizes.\"37-38\"");
}

TEST(TomlReader, ReadsCheckedValuesAndRefusesWhatItDidNotRead) {
  const toml::table doc = parsed("a = 1\nb = 2.5\nc = \"x\"\n[t]\nd = [1, 2]\n");
  TableReader root(doc, "f.toml", "");
  EXPECT_EQ(root.integer("a"), 1);
  EXPECT_DOUBLE_EQ(root.number("a"), 1.0);
  EXPECT_DOUBLE_EQ(number_above(root, "b", 2.0), 2.5);
  EXPECT_TRUE(root.has("c"));
  EXPECT_FALSE(root.has("e"));
  TableReader t = root.table("t");
  EXPECT_EQ(t.array("d").size(), 2U);
  t.finish();
  EXPECT_EQ(refusal([&] { root.finish(); }), "c: unknown key (line 3)");
  EXPECT_EQ(root.string("c"), "x");
  root.finish();
}

TEST(TomlReader, RefusesAMissingKeyAWrongTypeAndAValueOutOfRange) {
  const toml::table doc = parsed("a = 1\nb = \"x\"\nc = 7\n[t]\nd = true\n");
  TableReader root(doc, "f.toml", "");
  EXPECT_EQ(refusal([&] { root.number("z"); }), "z: missing");
  EXPECT_EQ(refusal([&] { root.number("b"); }), "b: expected a number, got a string (line 2)");
  EXPECT_EQ(refusal([&] { root.string("a"); }), "a: expected a string, got an integer (line 1)");
  EXPECT_EQ(refusal([&] { number_above(root, "a", 1.0); }), "a: must be > 1, got 1 (line 1)");
  EXPECT_EQ(refusal([&] { number_at_least(root, "a", 2.0); }), "a: must be >= 2, got 1 (line 1)");
  EXPECT_EQ(refusal([&] { integer_in(root, "c", 0, 5); }), "c: must be in [0, 5], got 7 (line 3)");
  EXPECT_EQ(refusal([&] { number_in(root, "c", 0.5, 6.5); }),
            "c: must be in [0.5, 6.5], got 7 (line 3)");
  EXPECT_DOUBLE_EQ(number_in(root, "c", 7.0, 7.0), 7.0);
  TableReader t = root.table("t");
  EXPECT_EQ(refusal([&] { t.integer("d"); }), "t.d: expected an integer, got a boolean (line 5)");
  EXPECT_EQ(refusal([&] { root.table("a"); }), "a: expected a table, got an integer (line 1)");
}

TEST(TomlReader, AnUnreadableFileOrBadSyntaxNamesTheFileAndWhere) {
  const auto dir = test::scratch_dir("toml-reader");
  try {
    parse_document(dir / "none.toml", "main.toml", "insoles_file");
    ADD_FAILURE() << "no ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.file(), "main.toml");
    EXPECT_EQ(e.key(), "insoles_file");
    EXPECT_NE(e.reason().find("none.toml: no such file"), std::string::npos) << e.what();
  }
  const auto bad = test::write_text(dir / "bad.toml", "a = 1\nb = [\n");
  try {
    parse_document(bad, bad.string(), "(file)");
    ADD_FAILURE() << "no ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.file(), bad.string());
    EXPECT_EQ(e.key(), "(syntax)");
    EXPECT_EQ(e.reason().rfind("line ", 0), 0U) << e.what();
  }
}

}  // namespace
}  // namespace gaitmon::detail
