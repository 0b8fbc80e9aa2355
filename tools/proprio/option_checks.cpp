#include "option_checks.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>

#include "proprio/core/file_io.hpp"

namespace proprio::cli {
namespace {

std::string shown(const std::string& text) { return "'" + printable(text, 40) + "'"; }

bool all_digits(const std::string& s, std::size_t from) {
  if (from >= s.size()) return false;
  for (std::size_t i = from; i < s.size(); ++i) {
    if (s[i] < '0' || s[i] > '9') return false;
  }
  return true;
}

// The base type CLI11 gives an option ("FLOAT", "UINT", "INT", "TEXT", ...),
// without the descriptions its validators append after ':'.
std::string base_type(const CLI::Option& opt) {
  std::string t = opt.get_type_name();
  if (const auto colon = t.find(':'); colon != std::string::npos) t.resize(colon);
  return t;
}

}  // namespace

std::string check_finite_number(const std::string& text) {
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size()) return shown(text) + " is not a number";
  if (!std::isfinite(v) || (errno == ERANGE && std::fabs(v) > 1.0)) return shown(text) + " is not a finite number";
  return {};
}

std::string check_unsigned_integer(const std::string& text) {
  const std::size_t from = (!text.empty() && text[0] == '+') ? 1 : 0;
  if (!all_digits(text, from)) {
    return shown(text) + " is not a whole number of 0 or more (decimal digits only)";
  }
  errno = 0;
  (void)std::strtoull(text.c_str(), nullptr, 10);
  if (errno == ERANGE) return shown(text) + " is too large (at most 18446744073709551615)";
  return {};
}

std::string check_signed_integer(const std::string& text) {
  const std::size_t from = (!text.empty() && (text[0] == '+' || text[0] == '-')) ? 1 : 0;
  if (!all_digits(text, from)) return shown(text) + " is not a whole number (decimal digits only)";
  errno = 0;
  (void)std::strtoll(text.c_str(), nullptr, 10);
  if (errno == ERANGE) return shown(text) + " is out of range";
  return {};
}

void harden_numeric_options(CLI::App& app) {
  for (CLI::Option* opt : app.get_options()) {
    const std::string type = base_type(*opt);
    if (type == "FLOAT") {
      opt->check(CLI::Validator(check_finite_number, "", "finite"));
    } else if (type == "UINT") {
      opt->check(CLI::Validator(check_unsigned_integer, "", "unsigned"));
    } else if (type == "INT") {
      opt->check(CLI::Validator(check_signed_integer, "", "signed"));
    }
  }
  for (CLI::App* sub : app.get_subcommands({})) harden_numeric_options(*sub);
}

}  // namespace proprio::cli
