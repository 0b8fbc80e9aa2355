#pragma once
// The CRC every Proprio HID report ends in (IMU glove board, stretch board,
// fingertip devices): the firmware side computes the same 256-entry table.
#include <cstdint>
#include <span>

namespace proprio::hid {

// CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final XOR;
// check value 0x29B1 for "123456789"). Chain by passing the previous result.
std::uint16_t crc16_ccitt(std::span<const std::uint8_t> data, std::uint16_t crc = 0xFFFF) noexcept;

}  // namespace proprio::hid
