#pragma once
#include <cstdint>

namespace proprio::hid {

// Every Proprio board enumerates under pid.codes' open-source vendor ID (each
// with its own test product ID, declared by its protocol) and puts its reports
// on a vendor-defined usage page, so a composite device's other interfaces
// (keyboard, serial console) are skipped.
inline constexpr std::uint16_t kPidCodesVendorId = 0x1209;
inline constexpr std::uint16_t kVendorDefinedUsagePage = 0xFF00;

}  // namespace proprio::hid
