// Formatter for board->PC lines. Each line is "<tag>\t<field>\t...", with an
// optional "\t*HH" CRC-8 token over everything before that tab, and "\n".
// Field order is the book's; PROTOCOL.md lists every line.
//
// Numbers are formatted from integers (fixed point), so no printf/float
// formatting code is linked on the board.
#ifndef CHEFBOT_CORE_LINE_FORMAT_H
#define CHEFBOT_CORE_LINE_FORMAT_H

#include <stddef.h>
#include <stdint.h>

#include "config.h"

namespace chefbot {

class LineBuilder {
 public:
  // Longest line the core emits is the `d` line, < 100 bytes.
  static const size_t kCapacity = 112;

  void begin(char tag);
  void add_int(int32_t v);
  void add_uint(uint32_t v);
  // Writes scaled / 10^decimals, e.g. (1235, 2) -> "12.35", (-5, 2) -> "-0.05".
  void add_fixed(int32_t scaled, uint8_t decimals);
  void add_text(const char* s);
  // Appends the checksum token (if asked) and '\n'. Returns the line length,
  // or 0 if the line did not fit (it is then not to be sent).
  size_t finish(bool checksum);

  const char* data() const { return buf_; }
  size_t size() const { return ok_ ? len_ : 0; }

 private:
  void put(char c);
  void put_digits(uint32_t v, uint8_t min_digits);

  char buf_[kCapacity];
  size_t len_ = 0;
  bool ok_ = true;
};

enum class DriveState : uint8_t {
  Idle,     // no command since reset: braked
  Run,      // last command younger than the watchdog timeout
  Timeout,  // watchdog tripped: braked until the next valid command
};
const char* drive_state_name(DriveState s);

struct Quaternion {
  float x = 0.0f;
  float y = 0.0f;
  float z = 0.0f;
  float w = 1.0f;
};

struct DiagCounters {
  uint32_t rx_ok = 0;
  uint32_t rx_errors = 0;
  uint32_t watchdog_trips = 0;
  uint32_t encoder_illegal_left = 0;
  uint32_t encoder_illegal_right = 0;
  uint32_t tx_dropped_lines = 0;
  uint32_t schedule_overruns = 0;
  uint32_t imu_ok = 0;  // 1 when the IMU delivered a valid sample recently
};

// Each returns the finished line length (0 only if it cannot fit).
size_t format_battery(LineBuilder& b, uint32_t millivolts, bool crc);
size_t format_time(LineBuilder& b, uint32_t micros, uint32_t period_us, bool crc);
size_t format_encoders(LineBuilder& b, int32_t left, int32_t right, bool crc);
size_t format_ultrasonic(LineBuilder& b, uint32_t cm, bool crc);
size_t format_speed(LineBuilder& b, int32_t left, int32_t right, DriveState state, bool crc);
size_t format_imu(LineBuilder& b, const Quaternion& q, bool crc);
size_t format_hello(LineBuilder& b, const Config& cfg, bool crc);
size_t format_diag(LineBuilder& b, const DiagCounters& d, bool crc);

// Worst-case lengths (with checksum), used for the serial budget.
static const size_t kMaxLenBattery = 1 + 1 + 6 + 4 + 1;                   // b\t655.35\t*HH\n
static const size_t kMaxLenTime = 1 + 1 + 10 + 1 + 7 + 4 + 1;            // t\t4294967295\t999.999
static const size_t kMaxLenEncoders = 1 + 2 * (1 + 11) + 4 + 1;          // e\t-2147483648\t...
static const size_t kMaxLenUltrasonic = 1 + 1 + 3 + 4 + 1;               // u\t400
static const size_t kMaxLenSpeed = 1 + 2 * (1 + 8) + 1 + 7 + 4 + 1;      // s\t-1023.00\t-1023.00\ttimeout
static const size_t kMaxLenImu = 1 + 4 * (1 + 7) + 4 + 1;                // i\t-1.0000 x4
static const size_t kMaxLenDiag = 1 + 8 * (1 + 10) + 4 + 1;
static const size_t kMaxStatusCycleBytes = kMaxLenBattery + kMaxLenTime + kMaxLenEncoders +
                                           kMaxLenUltrasonic + kMaxLenSpeed + kMaxLenImu;

}  // namespace chefbot

#endif
