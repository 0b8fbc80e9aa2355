#pragma once
// Small CSV reading and writing (RFC 4180 quoting) with errors that name the
// file, line and column. Blank lines and lines starting with '#' are skipped.
#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/result.hpp"

namespace proprio::study {

struct CsvTable {
  std::string source;                          // file name, for messages
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;  // each as wide as the header
  std::vector<int> lines;                      // 1-based source line of each row

  std::optional<std::size_t> column(std::string_view name) const;
  // The column's index, or an error listing the columns there are.
  Result<std::size_t> require_column(std::string_view name) const;
  // A finite number, or an error naming file:line and the column.
  Result<double> number(std::size_t row, std::size_t column) const;
  // A whole number (e.g. a count), with the same errors.
  Result<long long> integer(std::size_t row, std::size_t column) const;
};

Result<CsvTable> parse_csv(std::string_view text, std::string source_name = "<csv>");
Result<CsvTable> read_csv(const std::filesystem::path& path);

// A field quoted when it holds a comma, quote or line break.
std::string csv_field(std::string_view text);

}  // namespace proprio::study
