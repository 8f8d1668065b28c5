#include "crc8.h"

namespace chefbot {

uint8_t crc8_update(uint8_t crc, uint8_t byte) {
  uint32_t c = static_cast<uint32_t>(crc ^ byte);
  for (int i = 0; i < 8; ++i) c = (c & 0x80u) ? ((c << 1) ^ 0x07u) : (c << 1);
  return static_cast<uint8_t>(c);
}

uint8_t crc8(const char* data, size_t len) {
  uint8_t crc = 0;
  for (size_t i = 0; i < len; ++i) crc = crc8_update(crc, static_cast<uint8_t>(data[i]));
  return crc;
}

}  // namespace chefbot
