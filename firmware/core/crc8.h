// CRC-8/SMBUS (poly 0x07, init 0x00, no reflection; check("123456789") = 0xF4).
// Chosen over a plain XOR because it also catches two flipped bits in the
// same bit column, and it is tiny without a table.
#ifndef CHEFBOT_CORE_CRC8_H
#define CHEFBOT_CORE_CRC8_H

#include <stddef.h>
#include <stdint.h>

namespace chefbot {

uint8_t crc8_update(uint8_t crc, uint8_t byte);
uint8_t crc8(const char* data, size_t len);

}  // namespace chefbot

#endif
