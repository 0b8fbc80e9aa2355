// Fuzzes the study CSV reader (parse_csv) over arbitrary bytes: any input must
// end in an Error or a table whose rows are all as wide as the header, with
// increasing line numbers, and whose cells read as finite numbers or give an
// Error; without crash, hang or outsized allocation. Seeds: corpus/csv_reader/.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "proprio/study/csv.hpp"

using namespace proprio::study;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  auto table = parse_csv(text, "fuzz.csv");
  if (!table) {
    if (table.error().message.empty()) std::abort();
    return 0;
  }
  if (table->rows.size() != table->lines.size()) std::abort();
  int last_line = 0;
  for (std::size_t r = 0; r < table->rows.size(); ++r) {
    if (table->rows[r].size() != table->header.size()) std::abort();
    if (table->lines[r] <= last_line) std::abort();
    last_line = table->lines[r];
    // Cells of the first rows through the numeric readers (all rows would
    // make a large input quadratic in nothing but time).
    if (r >= 64) continue;
    for (std::size_t c = 0; c < table->header.size() && c < 64; ++c) {
      auto v = table->number(r, c);
      if (v && !std::isfinite(*v)) std::abort();
      auto i = table->integer(r, c);
      if (i && v && static_cast<double>(*i) != *v) std::abort();
    }
  }
  for (std::size_t c = 0; c < table->header.size() && c < 64; ++c) {
    auto found = table->require_column(table->header[c]);
    if (!found || *found > c) std::abort();  // the first column of that name
  }
  // A name no header has is not found (the fuzzer may well write this one into a header).
  const std::string absent = "\x01no such column";
  const bool present = std::find(table->header.begin(), table->header.end(), absent) != table->header.end();
  if (!present && table->require_column(absent)) std::abort();
  // What csv_field writes reads back as the same field.
  if (!table->header.empty()) {
    std::string line = "x,";
    const std::string& f = table->header.front();
    line += csv_field(f) + "\n1,2\n";
    auto again = parse_csv(line, "again.csv");
    const bool trimmed = f.find_first_of(" \t") == 0 || (!f.empty() && (f.back() == ' ' || f.back() == '\t'));
    if (!again || again->header.size() != 2 || (!trimmed && again->header[1] != f)) std::abort();
  }
  return 0;
}
