#include "line_format.h"

#include "crc8.h"

namespace chefbot {

namespace {

const uint32_t kPow10[] = {1u, 10u, 100u, 1000u, 10000u, 100000u, 1000000u};

// Rounded division that cannot overflow near UINT32_MAX.
uint32_t div_round(uint32_t v, uint32_t d) { return v / d + ((v % d) >= (d + 1u) / 2u ? 1u : 0u); }

int32_t round_to_int(float v) { return static_cast<int32_t>(v >= 0.0f ? v + 0.5f : v - 0.5f); }

int32_t quat_component_e4(float v) {
  // A non-finite or out-of-range component never reaches here in normal
  // operation (the core rejects such samples); clamp anyway so the text
  // always parses.
  if (!(v == v)) return 0;
  if (v > 1.0f) v = 1.0f;
  if (v < -1.0f) v = -1.0f;
  return round_to_int(v * 10000.0f);
}

}  // namespace

void LineBuilder::begin(char tag) {
  len_ = 0;
  ok_ = true;
  put(tag);
}

void LineBuilder::put(char c) {
  if (len_ < kCapacity) {
    buf_[len_++] = c;
  } else {
    ok_ = false;
  }
}

void LineBuilder::put_digits(uint32_t v, uint8_t min_digits) {
  char tmp[10];
  uint8_t n = 0;
  do {
    tmp[n++] = static_cast<char>('0' + v % 10u);
    v /= 10u;
  } while (v != 0u);
  while (n < min_digits && n < sizeof(tmp)) tmp[n++] = '0';
  while (n > 0) put(tmp[--n]);
}

void LineBuilder::add_uint(uint32_t v) {
  put('\t');
  put_digits(v, 1);
}

void LineBuilder::add_int(int32_t v) {
  put('\t');
  // Negate in unsigned arithmetic: -INT32_MIN does not exist as int32_t.
  uint32_t mag = static_cast<uint32_t>(v);
  if (v < 0) {
    put('-');
    mag = 0u - mag;
  }
  put_digits(mag, 1);
}

void LineBuilder::add_fixed(int32_t scaled, uint8_t decimals) {
  if (decimals > 6) decimals = 6;
  put('\t');
  uint32_t mag = static_cast<uint32_t>(scaled);
  if (scaled < 0) {
    put('-');
    mag = 0u - mag;
  }
  const uint32_t div = kPow10[decimals];
  put_digits(mag / div, 1);
  if (decimals > 0) {
    put('.');
    put_digits(mag % div, decimals);
  }
}

void LineBuilder::add_text(const char* s) {
  put('\t');
  while (*s) put(*s++);
}

size_t LineBuilder::finish(bool checksum) {
  if (checksum && ok_) {
    static const char kHex[] = "0123456789ABCDEF";
    const uint8_t crc = crc8(buf_, len_);
    put('\t');
    put('*');
    put(kHex[crc >> 4]);
    put(kHex[crc & 0x0Fu]);
  }
  put('\n');
  if (!ok_) len_ = 0;
  return len_;
}

const char* drive_state_name(DriveState s) {
  switch (s) {
    case DriveState::Idle: return "idle";
    case DriveState::Run: return "run";
    case DriveState::Timeout: return "timeout";
  }
  return "?";
}

size_t format_battery(LineBuilder& b, uint32_t millivolts, bool crc) {
  uint32_t cv = div_round(millivolts, 10u);  // centivolts
  if (cv > 65535u) cv = 65535u;
  b.begin('b');
  b.add_fixed(static_cast<int32_t>(cv), 2);
  return b.finish(crc);
}

size_t format_time(LineBuilder& b, uint32_t micros, uint32_t period_us, bool crc) {
  uint32_t ms = div_round(period_us, 1000u);
  if (ms > 999999u) ms = 999999u;
  b.begin('t');
  b.add_uint(micros);
  b.add_fixed(static_cast<int32_t>(ms), 3);
  return b.finish(crc);
}

size_t format_encoders(LineBuilder& b, int32_t left, int32_t right, bool crc) {
  b.begin('e');
  b.add_int(left);
  b.add_int(right);
  return b.finish(crc);
}

size_t format_ultrasonic(LineBuilder& b, uint32_t cm, bool crc) {
  b.begin('u');
  b.add_uint(cm);
  return b.finish(crc);
}

size_t format_speed(LineBuilder& b, int32_t left, int32_t right, DriveState state, bool crc) {
  // The echo keeps the book's "0.00" look; commands are integers, so the
  // fraction is always .00. Multiplying by 100 cannot overflow: |cmd| is
  // clamped to command_max long before this.
  b.begin('s');
  b.add_fixed(left * 100, 2);
  b.add_fixed(right * 100, 2);
  b.add_text(drive_state_name(state));
  return b.finish(crc);
}

size_t format_imu(LineBuilder& b, const Quaternion& q, bool crc) {
  b.begin('i');
  b.add_fixed(quat_component_e4(q.x), 4);
  b.add_fixed(quat_component_e4(q.y), 4);
  b.add_fixed(quat_component_e4(q.z), 4);
  b.add_fixed(quat_component_e4(q.w), 4);
  return b.finish(crc);
}

size_t format_hello(LineBuilder& b, const Config& cfg, bool crc) {
  b.begin('v');
  b.add_int(kProtocolVersion);
  b.add_text(kFirmwareVersion);
  b.add_uint(cfg.status_rate_hz);
  b.add_uint(cfg.watchdog_ms);
  b.add_uint(static_cast<uint32_t>(cfg.encoder_mode));
  b.add_int(cfg.command_max);
  return b.finish(crc);
}

size_t format_diag(LineBuilder& b, const DiagCounters& d, bool crc) {
  b.begin('d');
  b.add_uint(d.rx_ok);
  b.add_uint(d.rx_errors);
  b.add_uint(d.watchdog_trips);
  b.add_uint(d.encoder_illegal_left);
  b.add_uint(d.encoder_illegal_right);
  b.add_uint(d.tx_dropped_lines);
  b.add_uint(d.schedule_overruns);
  b.add_uint(d.imu_ok);
  return b.finish(crc);
}

}  // namespace chefbot

// Out-of-line definition: C++11 needs one when the constant is odr-used.
const size_t chefbot::LineBuilder::kCapacity;
