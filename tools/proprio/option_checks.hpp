#pragma once
// One validator for every numeric option of the CLI, present and future.
//
// CLI11 accepts "nan" and "inf" for a double (and NaN passes CLI::Range, whose
// comparisons are all false), parses integers with strtoull/strtoll in base 0
// ("-1" wraps to 2^64-1 in an unsigned, "010" is octal). harden_numeric_options
// walks the whole command tree once, after every command is added, and checks
// each option by the type CLI11 gives it: FLOAT must be a finite number, UINT a
// plain decimal number without a sign, INT a plain decimal number.
#include <CLI/CLI.hpp>
#include <string>

namespace proprio::cli {

void harden_numeric_options(CLI::App& app);

// The checks themselves: an empty string when `text` is acceptable, else why not.
std::string check_finite_number(const std::string& text);
std::string check_unsigned_integer(const std::string& text);
std::string check_signed_integer(const std::string& text);

}  // namespace proprio::cli
