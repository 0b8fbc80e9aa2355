#pragma once
// Result<T>: a value or an Error a user can act on. Used at every boundary where
// input may be bad (files, configs, devices), in the spirit of vk-bootstrap.
#include <cassert>
#include <string>
#include <utility>
#include <variant>

namespace proprio {

enum class Errc {
  invalid_argument,  // caller passed something out of range / malformed
  not_found,         // file, key or device is not there
  parse_error,       // bytes or text did not follow the format
  io_error,          // the OS refused a read or write
  unsupported,       // valid, but this build or version cannot do it
  out_of_range,      // request outside what the data can serve (e.g. pose time)
  unavailable,       // source exists but has nothing to offer right now
};

const char* to_string(Errc code) noexcept;

struct Error {
  Errc code = Errc::invalid_argument;
  std::string message;  // what went wrong, where, and what to do about it

  // Prefix context ("while loading foo.toml: ...") as errors travel upward.
  Error with_context(const std::string& context) const {
    return Error{code, context + ": " + message};
  }
};

template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value) : storage_(std::move(value)) {}  // NOLINT: implicit by design
  Result(Error error) : storage_(std::move(error)) {}  // NOLINT

  bool ok() const noexcept { return std::holds_alternative<T>(storage_); }
  explicit operator bool() const noexcept { return ok(); }

  T& value() & { assert(ok()); return std::get<T>(storage_); }
  const T& value() const& { assert(ok()); return std::get<T>(storage_); }
  T&& value() && { assert(ok()); return std::get<T>(std::move(storage_)); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }

  const Error& error() const { assert(!ok()); return std::get<Error>(storage_); }
  T value_or(T fallback) const { return ok() ? value() : std::move(fallback); }

 private:
  std::variant<T, Error> storage_;
};

// Result<void> equivalent.
class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(Error error) : error_(std::move(error)), ok_(false) {}  // NOLINT
  static Status success() { return {}; }
  bool ok() const noexcept { return ok_; }
  explicit operator bool() const noexcept { return ok_; }
  const Error& error() const { assert(!ok_); return error_; }

 private:
  Error error_;
  bool ok_ = true;
};

inline Error make_error(Errc code, std::string message) { return Error{code, std::move(message)}; }

}  // namespace proprio
