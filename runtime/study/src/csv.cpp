#include "proprio/study/csv.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fmt/format.h>

#include "proprio/core/file_io.hpp"

namespace proprio::study {

std::optional<std::size_t> CsvTable::column(std::string_view name) const {
  for (std::size_t i = 0; i < header.size(); ++i) {
    if (header[i] == name) return i;
  }
  return std::nullopt;
}

Result<std::size_t> CsvTable::require_column(std::string_view name) const {
  if (auto c = column(name)) return *c;
  std::string have;
  for (const std::string& h : header) have += (have.empty() ? "" : ", ") + h;
  return make_error(Errc::not_found, fmt::format("{}: no column '{}' in the header (columns: {})", source,
                                                 printable(name, 60), printable(have, 300)));
}

Result<double> CsvTable::number(std::size_t row, std::size_t col) const {
  const std::string& text = rows[row][col];
  const char* begin = text.c_str();
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(begin, &end);
  const bool parsed = end != begin && *end == '\0' && errno != ERANGE;
  if (!parsed || !std::isfinite(v)) {
    return make_error(Errc::parse_error,
                      fmt::format("{}:{}: column '{}' holds '{}', which is not a finite number", source, lines[row],
                                  printable(header[col], 60), printable(text, 60)));
  }
  return v;
}

Result<long long> CsvTable::integer(std::size_t row, std::size_t col) const {
  Result<double> v = number(row, col);
  if (!v) return v.error();
  if (*v != std::floor(*v) || std::abs(*v) > 9e15) {
    return make_error(Errc::parse_error,
                      fmt::format("{}:{}: column '{}' holds '{}', which is not a whole number", source, lines[row],
                                  printable(header[col], 60), printable(rows[row][col], 60)));
  }
  return static_cast<long long>(*v);
}

Result<CsvTable> parse_csv(std::string_view text, std::string source_name) {
  CsvTable table;
  table.source = std::move(source_name);
  // Spreadsheet programs save "UTF-8 CSV" with a byte-order mark, which
  // would otherwise become part of the first column's name.
  std::size_t i = text.substr(0, 3) == "\xEF\xBB\xBF" ? 3 : 0;
  int line = 1;
  bool have_header = false;
  while (i < text.size()) {
    const int record_line = line;
    // Skip blank and comment lines.
    if (text[i] == '\n' || text[i] == '\r' || text[i] == '#') {
      while (i < text.size() && text[i] != '\n') ++i;
      if (i < text.size()) ++i;
      ++line;
      continue;
    }
    std::vector<std::string> fields;
    std::string field;
    bool in_quotes = false, field_was_quoted = false;
    for (; i < text.size(); ++i) {
      const char c = text[i];
      if (in_quotes) {
        if (c == '"') {
          if (i + 1 < text.size() && text[i + 1] == '"') {
            field += '"';
            ++i;
          } else {
            in_quotes = false;
          }
        } else {
          if (c == '\n') ++line;
          field += c;
        }
        continue;
      }
      if (c == '"' && field.empty() && !field_was_quoted) {
        in_quotes = field_was_quoted = true;
      } else if (c == ',') {
        fields.push_back(std::move(field));
        field.clear();
        field_was_quoted = false;
      } else if (c == '\n') {
        break;
      } else if (c != '\r') {
        field += c;
      }
    }
    if (in_quotes) {
      return make_error(Errc::parse_error,
                        fmt::format("{}:{}: a quoted field is never closed; every '\"' that opens a field needs a "
                                    "closing '\"'",
                                    table.source, record_line));
    }
    fields.push_back(std::move(field));
    if (i < text.size()) ++i;  // the '\n'
    ++line;
    for (std::string& f : fields) {
      // Trim spaces around unquoted numbers and names ("0.5, 12").
      const auto b = f.find_first_not_of(" \t");
      const auto e = f.find_last_not_of(" \t");
      f = b == std::string::npos ? std::string() : f.substr(b, e - b + 1);
    }
    if (!have_header) {
      table.header = std::move(fields);
      have_header = true;
      continue;
    }
    if (fields.size() != table.header.size()) {
      return make_error(Errc::parse_error,
                        fmt::format("{}:{}: {} fields, but the header has {} columns", table.source, record_line,
                                    fields.size(), table.header.size()));
    }
    table.rows.push_back(std::move(fields));
    table.lines.push_back(record_line);
  }
  if (!have_header) {
    return make_error(Errc::parse_error, fmt::format("{}: the file is empty; expected a header line", table.source));
  }
  return table;
}

Result<CsvTable> read_csv(const std::filesystem::path& path) {
  auto text = read_input_file(path, "CSV file");
  if (!text) return text.error();
  return parse_csv(*text, printable(path.string()));
}

std::string csv_field(std::string_view text) {
  if (text.find_first_of(",\"\n\r") == std::string_view::npos) return std::string(text);
  std::string out = "\"";
  for (char c : text) {
    if (c == '"') out += '"';
    out += c;
  }
  out += '"';
  return out;
}

}  // namespace proprio::study
