#include "proprio/core/config.hpp"

#include "proprio/core/file_io.hpp"

#include <toml++/toml.h>

#include <cmath>
#include <fstream>
#include <sstream>

namespace proprio {

struct Config::Impl {
  std::shared_ptr<const toml::table> root;  // keeps the document alive for sub-tables
  const toml::table* table = nullptr;
  std::string source;
  std::string prefix;  // dotted path of this table within the file, for messages
};

namespace {

std::string full_key(const Config::Impl& impl, std::string_view key) {
  return impl.prefix.empty() ? std::string(key) : impl.prefix + "." + std::string(key);
}

std::string where_in(const Config::Impl& impl, const toml::node* node) {
  std::ostringstream s;
  s << impl.source;
  if (node && node->source().begin.line > 0) s << ':' << node->source().begin.line << ':' << node->source().begin.column;
  return s.str();
}

const char* type_name(const toml::node& n) {
  switch (n.type()) {
    case toml::node_type::table: return "a table";
    case toml::node_type::array: return "an array";
    case toml::node_type::string: return "a string";
    case toml::node_type::integer: return "an integer";
    case toml::node_type::floating_point: return "a number";
    case toml::node_type::boolean: return "a boolean";
    case toml::node_type::date:
    case toml::node_type::time:
    case toml::node_type::date_time: return "a date/time";
    default: return "nothing";
  }
}

Error missing(const Config::Impl& impl, std::string_view key) {
  return make_error(Errc::not_found, impl.source + ": required key '" + full_key(impl, key) +
                                         "' is missing; add it to the file");
}

Error wrong_type(const Config::Impl& impl, std::string_view key, const toml::node& n, const std::string& expected) {
  return make_error(Errc::invalid_argument, where_in(impl, &n) + ": '" + full_key(impl, key) + "' must be " +
                                                expected + ", but it is " + type_name(n));
}

const toml::node* find(const Config::Impl& impl, std::string_view key) {
  return impl.table->at_path(key).node();
}

template <typename T>
std::string to_text(T v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

template <typename T>
Result<T> check_range(const Config::Impl& impl, std::string_view key, const toml::node& n, T v, T min, T max) {
  if (v < min || v > max) {
    return make_error(Errc::out_of_range, where_in(impl, &n) + ": '" + full_key(impl, key) + "' = " + to_text(v) +
                                              " is outside the allowed range [" + to_text(min) + ", " +
                                              to_text(max) + "]");
  }
  return v;
}

}  // namespace

Result<Config> Config::parse(std::string_view toml_text, std::string source_name) {
  try {
    auto root = std::make_shared<const toml::table>(toml::parse(toml_text, source_name));
    auto impl = std::make_shared<Impl>();
    impl->table = root.get();
    impl->root = std::move(root);
    impl->source = std::move(source_name);
    return Config(std::move(impl));
  } catch (const toml::parse_error& e) {
    std::ostringstream s;
    s << source_name << ':' << e.source().begin.line << ':' << e.source().begin.column
      << ": TOML syntax error: " << e.description();
    return make_error(Errc::parse_error, s.str());
  }
}

Result<Config> Config::load_file(const std::filesystem::path& path) {
  // TOML files are hand-written configuration: 16 MiB is far beyond any.
  auto text = read_input_file(path, "config file", 16 * kMiB);
  if (!text) return text.error();
  return parse(*text, path.string());
}

Result<bool> Config::get_bool(std::string_view key) const {
  const auto* n = find(*impl_, key);
  if (!n) return missing(*impl_, key);
  if (auto v = n->value_exact<bool>()) return *v;
  return wrong_type(*impl_, key, *n, "true or false");
}

Result<std::int64_t> Config::get_int(std::string_view key) const {
  const auto* n = find(*impl_, key);
  if (!n) return missing(*impl_, key);
  if (auto v = n->value_exact<std::int64_t>()) return *v;
  return wrong_type(*impl_, key, *n, "an integer");
}

Result<double> Config::get_double(std::string_view key) const {
  const auto* n = find(*impl_, key);
  if (!n) return missing(*impl_, key);
  if (n->is_integer()) return static_cast<double>(*n->value_exact<std::int64_t>());
  if (auto v = n->value_exact<double>()) {
    if (!std::isfinite(*v)) {
      return make_error(Errc::invalid_argument,
                        where_in(*impl_, n) + ": '" + full_key(*impl_, key) + "' must be a finite number");
    }
    return *v;
  }
  return wrong_type(*impl_, key, *n, "a number");
}

Result<std::string> Config::get_string(std::string_view key) const {
  const auto* n = find(*impl_, key);
  if (!n) return missing(*impl_, key);
  if (auto v = n->value_exact<std::string>()) return *v;
  return wrong_type(*impl_, key, *n, "a string");
}

Result<std::vector<double>> Config::get_doubles(std::string_view key) const {
  const auto* n = find(*impl_, key);
  if (!n) return missing(*impl_, key);
  const auto* arr = n->as_array();
  if (!arr) return wrong_type(*impl_, key, *n, "an array of numbers");
  std::vector<double> out;
  out.reserve(arr->size());
  for (std::size_t i = 0; i < arr->size(); ++i) {
    const auto& e = *arr->get(i);
    if (e.is_integer()) {
      out.push_back(static_cast<double>(*e.value_exact<std::int64_t>()));
    } else if (auto v = e.value_exact<double>(); v && std::isfinite(*v)) {
      out.push_back(*v);
    } else {
      return make_error(Errc::invalid_argument, where_in(*impl_, &e) + ": element " + std::to_string(i) + " of '" +
                                                    full_key(*impl_, key) + "' must be a finite number, but it is " +
                                                    (e.is_floating_point() ? std::string("inf or nan")
                                                                           : std::string(type_name(e))));
    }
  }
  return out;
}

Result<std::vector<std::string>> Config::get_strings(std::string_view key) const {
  const auto* n = find(*impl_, key);
  if (!n) return missing(*impl_, key);
  const auto* arr = n->as_array();
  if (!arr) return wrong_type(*impl_, key, *n, "an array of strings");
  std::vector<std::string> out;
  for (std::size_t i = 0; i < arr->size(); ++i) {
    const auto& e = *arr->get(i);
    auto v = e.value_exact<std::string>();
    if (!v) {
      return make_error(Errc::invalid_argument, where_in(*impl_, &e) + ": element " + std::to_string(i) + " of '" +
                                                    full_key(*impl_, key) + "' must be a string, but it is " +
                                                    type_name(e));
    }
    out.push_back(*v);
  }
  return out;
}

Result<bool> Config::get_bool_or(std::string_view key, bool fallback) const {
  return contains(key) ? get_bool(key) : Result<bool>(fallback);
}

Result<std::int64_t> Config::get_int_or(std::string_view key, std::int64_t fallback, std::int64_t min,
                                        std::int64_t max) const {
  if (!contains(key)) return fallback;
  auto v = get_int(key);
  if (!v) return v;
  return check_range(*impl_, key, *find(*impl_, key), *v, min, max);
}

Result<double> Config::get_double_or(std::string_view key, double fallback, double min, double max) const {
  if (!contains(key)) return fallback;
  auto v = get_double(key);
  if (!v) return v;
  return check_range(*impl_, key, *find(*impl_, key), *v, min, max);
}

Result<std::string> Config::get_string_or(std::string_view key, std::string fallback) const {
  return contains(key) ? get_string(key) : Result<std::string>(std::move(fallback));
}

bool Config::contains(std::string_view key) const { return find(*impl_, key) != nullptr; }

Result<Config> Config::table(std::string_view key) const {
  const auto* n = find(*impl_, key);
  if (!n) return missing(*impl_, key);
  const auto* t = n->as_table();
  if (!t) return wrong_type(*impl_, key, *n, "a table");
  auto impl = std::make_shared<Impl>(*impl_);
  impl->table = t;
  impl->prefix = full_key(*impl_, key);
  return Config(std::move(impl));
}

Result<std::vector<Config>> Config::tables(std::string_view key) const {
  const auto* n = find(*impl_, key);
  if (!n) return missing(*impl_, key);
  const auto* arr = n->as_array();
  if (!arr) return wrong_type(*impl_, key, *n, "an array of tables ([[" + std::string(key) + "]])");
  std::vector<Config> out;
  for (std::size_t i = 0; i < arr->size(); ++i) {
    const auto* t = arr->get(i)->as_table();
    if (!t) return wrong_type(*impl_, key, *arr->get(i), "a table");
    auto impl = std::make_shared<Impl>(*impl_);
    impl->table = t;
    impl->prefix = full_key(*impl_, key) + "[" + std::to_string(i) + "]";
    out.push_back(Config(std::move(impl)));
  }
  return out;
}

std::vector<std::string> Config::keys() const {
  std::vector<std::string> out;
  for (const auto& [k, v] : *impl_->table) out.emplace_back(k.str());
  return out;
}

Status Config::check_keys(std::string_view table, const std::set<std::string>& known, std::string_view hint) const {
  for (const std::string& k : keys()) {
    if (known.count(k) == 0) {
      std::string list;
      for (const std::string& n : known) list += (list.empty() ? "" : ", ") + n;
      return make_error(Errc::invalid_argument, where(k) + ": unknown key '" + printable(k, 80) + "' in [" + std::string(table) +
                                                    "]; known keys: " + list +
                                                    (hint.empty() ? std::string() : " (" + std::string(hint) + ")"));
    }
  }
  return Status::success();
}

const std::string& Config::source_name() const noexcept { return impl_->source; }

std::string Config::where(std::string_view key) const { return where_in(*impl_, find(*impl_, key)); }

}  // namespace proprio
