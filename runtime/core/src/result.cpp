#include "proprio/core/result.hpp"

namespace proprio {

const char* to_string(Errc code) noexcept {
  switch (code) {
    case Errc::invalid_argument: return "invalid argument";
    case Errc::not_found: return "not found";
    case Errc::parse_error: return "parse error";
    case Errc::io_error: return "I/O error";
    case Errc::unsupported: return "unsupported";
    case Errc::out_of_range: return "out of range";
    case Errc::unavailable: return "unavailable";
  }
  return "unknown error";
}

}  // namespace proprio
