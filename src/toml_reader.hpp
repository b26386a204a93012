// Reading gaitmon's TOML files (the config and the calibration designs): every value checked,
// every unknown key refused, and every error naming the file, the key and the line.
#pragma once

#include <toml++/toml.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <set>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "gaitmon/error.hpp"

namespace gaitmon::detail {

/// `key` as a dotted path writes it, quoted where it is not a bare key ("37-38").
std::string key_text(std::string_view key);
std::string child_path(const std::string& parent, std::string_view key);
std::string_view type_text(const toml::node& node);
/// "expected `what`, got <the node's type>".
std::string expected(std::string_view what, const toml::node& node);
/// " (line N)" for a node that knows its line, so that a person can find it in a long file.
std::string at_line(const toml::node& node);

// Reads one TOML table and remembers which keys were read, so that finish() can refuse all
// others: supporting a new key or section is one more read call, and a misspelt key is never
// silently ignored.
class TableReader {
 public:
  TableReader(const toml::table& table, std::string file, std::string path)
      : table_(&table), file_(std::move(file)), path_(std::move(path)) {}

  const std::string& file() const { return file_; }
  std::string key_path(std::string_view key) const { return child_path(path_, key); }

  [[noreturn]] void fail(std::string_view key, const std::string& reason) const {
    const toml::node* node = table_->get(key);
    throw ConfigError(file_, key_path(key), node == nullptr ? reason : reason + at_line(*node));
  }
  [[noreturn]] void fail_here(const std::string& reason) const {
    throw ConfigError(file_, path_, reason + at_line(*table_));
  }

  std::vector<std::string> keys() const {
    std::vector<std::string> out;
    for (auto&& [key, value] : *table_) out.emplace_back(key.str());
    return out;
  }

  bool has(std::string_view key) const { return table_->contains(key); }

  const toml::node& node(std::string_view key) {
    const toml::node* found = table_->get(key);
    if (found == nullptr) fail(key, "missing");
    read_.emplace(key);
    return *found;
  }

  double number(std::string_view key) {
    const toml::node& n = node(key);
    double value = 0.0;
    if (const auto* i = n.as_integer()) {
      value = static_cast<double>(i->get());
    } else if (const auto* f = n.as_floating_point()) {
      value = f->get();
    } else {
      fail(key, expected("a number", n));
    }
    if (!std::isfinite(value)) fail(key, "must be a finite number");
    return value;
  }

  std::int64_t integer(std::string_view key) {
    const toml::node& n = node(key);
    const auto* i = n.as_integer();
    if (i == nullptr) fail(key, expected("an integer", n));
    return i->get();
  }

  std::string string(std::string_view key) {
    const toml::node& n = node(key);
    const auto* s = n.as_string();
    if (s == nullptr) fail(key, expected("a string", n));
    return s->get();
  }

  const toml::array& array(std::string_view key) {
    const toml::node& n = node(key);
    const auto* a = n.as_array();
    if (a == nullptr) fail(key, expected("an array", n));
    return *a;
  }

  TableReader table(std::string_view key) {
    const toml::node& n = node(key);
    const auto* t = n.as_table();
    if (t == nullptr) fail(key, expected("a table", n));
    return TableReader(*t, file_, key_path(key));
  }

  void finish() const {
    for (auto&& [key, value] : *table_) {
      if (!read_.contains(key.str())) fail(key.str(), "unknown key");
    }
  }

 private:
  const toml::table* table_;
  std::string file_;
  std::string path_;
  std::set<std::string, std::less<>> read_;
};

/// ConfigError for one element of an array under `key`, at the element's line.
[[noreturn]] void fail_element(const std::string& file, const std::string& key,
                               const toml::node& element, const std::string& reason);
double number_above(TableReader& table, std::string_view key, double floor);
double number_at_least(TableReader& table, std::string_view key, double floor);
double number_in(TableReader& table, std::string_view key, double low, double high);
int integer_in(TableReader& table, std::string_view key, int low, int high);

/// The TOML document at `path`; ConfigError naming `unreadable_file` and `unreadable_key` (where
/// the path was named) when it cannot be read, naming the path, line and column for bad syntax.
toml::table parse_document(const std::filesystem::path& path, const std::string& unreadable_file,
                           const std::string& unreadable_key);

}  // namespace gaitmon::detail
