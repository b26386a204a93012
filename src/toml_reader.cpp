// The TOML reading shared by the config and the calibration designs.
#include "toml_reader.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <sstream>

namespace gaitmon::detail {

namespace fs = std::filesystem;

// "37-38" is a valid bare key, but quoting it reads as a name rather than a subtraction and
// matches how the files write it.
std::string key_text(std::string_view key) {
  const bool bare = !key.empty() && std::all_of(key.begin(), key.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_';
  });
  return bare ? std::string(key) : fmt::format("\"{}\"", key);
}

std::string child_path(const std::string& parent, std::string_view key) {
  return parent.empty() ? key_text(key) : parent + "." + key_text(key);
}

std::string_view type_text(const toml::node& node) {
  switch (node.type()) {
    case toml::node_type::table:
      return "a table";
    case toml::node_type::array:
      return "an array";
    case toml::node_type::string:
      return "a string";
    case toml::node_type::integer:
      return "an integer";
    case toml::node_type::floating_point:
      return "a floating-point number";
    case toml::node_type::boolean:
      return "a boolean";
    case toml::node_type::date:
    case toml::node_type::time:
    case toml::node_type::date_time:
      return "a date or time";
    case toml::node_type::none:
      break;
  }
  return "nothing";
}

std::string expected(std::string_view what, const toml::node& node) {
  return fmt::format("expected {}, got {}", what, type_text(node));
}

// Appended to reasons so that a person can find the value in a long file.
std::string at_line(const toml::node& node) {
  const auto line = node.source().begin.line;
  return line > 0 ? fmt::format(" (line {})", line) : std::string();
}

void fail_element(const std::string& file, const std::string& key, const toml::node& element,
                  const std::string& reason) {
  throw ConfigError(file, key, reason + at_line(element));
}

double number_above(TableReader& table, std::string_view key, double floor) {
  const double value = table.number(key);
  if (!(value > floor)) table.fail(key, fmt::format("must be > {}, got {}", floor, value));
  return value;
}

double number_at_least(TableReader& table, std::string_view key, double floor) {
  const double value = table.number(key);
  if (!(value >= floor)) table.fail(key, fmt::format("must be >= {}, got {}", floor, value));
  return value;
}

double number_in(TableReader& table, std::string_view key, double low, double high) {
  const double value = table.number(key);
  if (!(value >= low && value <= high)) {
    table.fail(key, fmt::format("must be in [{}, {}], got {}", low, high, value));
  }
  return value;
}

int integer_in(TableReader& table, std::string_view key, int low, int high) {
  const std::int64_t value = table.integer(key);
  if (value < low || value > high) {
    table.fail(key, fmt::format("must be in [{}, {}], got {}", low, high, value));
  }
  return static_cast<int>(value);
}

toml::table parse_document(const fs::path& path, const std::string& unreadable_file,
                           const std::string& unreadable_key) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) {
    throw ConfigError(unreadable_file, unreadable_key,
                      fmt::format("cannot read {}: {}", path.string(),
                                  fs::exists(path, ec) ? "not a regular file" : "no such file"));
  }
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  if (!in) throw ConfigError(unreadable_file, unreadable_key, "cannot read " + path.string());
  try {
    return toml::parse(text.str(), path.string());
  } catch (const toml::parse_error& e) {
    throw ConfigError(path.string(), "(syntax)",
                      fmt::format("line {}, column {}: {}", e.source().begin.line,
                                  e.source().begin.column, e.description()));
  }
}

}  // namespace gaitmon::detail
