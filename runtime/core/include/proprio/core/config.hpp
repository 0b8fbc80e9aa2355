#pragma once
// TOML configuration with errors a user can act on: every message names the
// file, the line and the key, says what was expected and what was found.
// toml++ stays an implementation detail behind this small typed interface.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/result.hpp"

namespace proprio {

class Config {
 public:
  static Result<Config> load_file(const std::filesystem::path& path);
  // source_name appears in error messages in place of a file name.
  static Result<Config> parse(std::string_view toml_text, std::string source_name = "<string>");

  // Keys are dotted paths ("rig.baseline_m"). Required values: a missing key is
  // an Errc::not_found error. Integers are accepted where a double is asked.
  Result<bool> get_bool(std::string_view key) const;
  Result<std::int64_t> get_int(std::string_view key) const;
  Result<double> get_double(std::string_view key) const;
  Result<std::string> get_string(std::string_view key) const;
  Result<std::vector<double>> get_doubles(std::string_view key) const;
  Result<std::vector<std::string>> get_strings(std::string_view key) const;

  // Optional values: the fallback when absent, an error when present but of
  // the wrong type or outside [min, max] (a typo'd value must not pass silently).
  Result<bool> get_bool_or(std::string_view key, bool fallback) const;
  Result<std::int64_t> get_int_or(std::string_view key, std::int64_t fallback, std::int64_t min,
                                  std::int64_t max) const;
  Result<double> get_double_or(std::string_view key, double fallback, double min, double max) const;
  Result<std::string> get_string_or(std::string_view key, std::string fallback) const;

  bool contains(std::string_view key) const;
  // A sub-table as its own Config (same source name, keys relative to it).
  Result<Config> table(std::string_view key) const;
  // An array of tables ([[marker]] entries) as Configs.
  Result<std::vector<Config>> tables(std::string_view key) const;
  // Keys directly under this table, in file order.
  std::vector<std::string> keys() const;
  // A typo'd key must not pass silently: an error naming the first key that is
  // not in `known`, where it is, and the keys that are allowed. `table` names
  // the table in the message ("top level", "study", ...); `hint` (a docs
  // pointer) ends the message. Every TOML reader of Proprio uses this rule.
  Status check_keys(std::string_view table, const std::set<std::string>& known, std::string_view hint = {}) const;

  const std::string& source_name() const noexcept;
  // "file:line:col" of a key (dotted, relative to this table), or just the
  // file name when the key is absent: for errors only the caller can detect.
  std::string where(std::string_view key) const;

  struct Impl;

 private:
  explicit Config(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}
  std::shared_ptr<const Impl> impl_;
};

}  // namespace proprio
