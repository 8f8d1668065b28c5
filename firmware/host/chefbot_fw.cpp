#include "chefbot_fw.h"

#include <string.h>

#include <new>

#include "host_board.h"

using chefbot::Config;
using chefbot::EncoderMode;
using chefbot::Side;
using chefbot::host::HostBoard;

struct cfw_board {
  HostBoard board;
};

namespace {

Side side_of(int s) { return s ? chefbot::kRight : chefbot::kLeft; }

struct UKey {
  const char* name;
  uint32_t Config::*field;
};
struct BKey {
  const char* name;
  bool Config::*field;
};
struct U8Key {
  const char* name;
  uint8_t Config::*field;
};

const UKey kUKeys[] = {
    {"status_rate_hz", &Config::status_rate_hz},
    {"diag_every_cycles", &Config::diag_every_cycles},
    {"watchdog_ms", &Config::watchdog_ms},
    {"ultrasonic_period_ms", &Config::ultrasonic_period_ms},
    {"ultrasonic_max_cm", &Config::ultrasonic_max_cm},
    {"battery_r_top_ohm", &Config::battery_r_top_ohm},
    {"battery_r_bottom_ohm", &Config::battery_r_bottom_ohm},
    {"adc_ref_mv", &Config::adc_ref_mv},
    {"adc_max_raw", &Config::adc_max_raw},
    {"tx_buffer_bytes", &Config::tx_buffer_bytes},
    {"tx_bytes_per_s", &Config::tx_bytes_per_s},
};
const BKey kBKeys[] = {
    {"invert_left", &Config::invert_left},
    {"invert_right", &Config::invert_right},
    {"invert_left_encoder", &Config::invert_left_encoder},
    {"invert_right_encoder", &Config::invert_right_encoder},
    {"tx_checksum", &Config::tx_checksum},
};
const U8Key kU8Keys[] = {
    {"pwm_max", &Config::pwm_max},
    {"brake_pwm", &Config::brake_pwm},
};

template <typename T>
T clamp_to(int64_t v, int64_t lo, int64_t hi) {
  return static_cast<T>(v < lo ? lo : (v > hi ? hi : v));
}

}  // namespace

extern "C" {

int cfw_api_version(void) { return CFW_API_VERSION; }

cfw_board* cfw_create(void) { return new (std::nothrow) cfw_board(); }

void cfw_destroy(cfw_board* b) { delete b; }

int cfw_configure(cfw_board* b, const char* key, int64_t value) {
  if (!b || !key) return -1;
  Config& c = b->board.config();
  for (const UKey& k : kUKeys) {
    if (strcmp(key, k.name) == 0) {
      c.*(k.field) = clamp_to<uint32_t>(value, 0, 0xFFFFFFFFll);
      return 0;
    }
  }
  for (const BKey& k : kBKeys) {
    if (strcmp(key, k.name) == 0) {
      c.*(k.field) = value != 0;
      return 0;
    }
  }
  for (const U8Key& k : kU8Keys) {
    if (strcmp(key, k.name) == 0) {
      c.*(k.field) = clamp_to<uint8_t>(value, 0, 255);
      return 0;
    }
  }
  if (strcmp(key, "command_max") == 0) {
    c.command_max = clamp_to<int32_t>(value, 1, 9999);
    return 0;
  }
  if (strcmp(key, "encoder_mode") == 0) {
    if (value != 1 && value != 2 && value != 4) return -1;
    c.encoder_mode = static_cast<EncoderMode>(value);
    return 0;
  }
  if (strcmp(key, "loop_us") == 0) {
    b->board.set_loop_us(clamp_to<uint32_t>(value, 1, 1000000));
    return 0;
  }
  if (strcmp(key, "instant_tx") == 0) {
    b->board.set_instant_tx(value != 0);
    return 0;
  }
  return -1;
}

void cfw_power_on(cfw_board* b) { b->board.power_on(); }

size_t cfw_feed(cfw_board* b, const uint8_t* data, size_t len) { return data ? b->board.feed(data, len) : 0; }
void cfw_advance(cfw_board* b, uint64_t us) { b->board.advance(us); }
void cfw_poll(cfw_board* b) { b->board.poll_once(); }
uint32_t cfw_now_us(cfw_board* b) { return b->board.now(); }
void cfw_set_clock_us(cfw_board* b, uint32_t us) { b->board.set_clock(us); }

size_t cfw_tx_available(cfw_board* b) { return b->board.tx_available(); }
size_t cfw_read_tx(cfw_board* b, uint8_t* out, size_t max) { return out ? b->board.read_tx(out, max) : 0; }

void cfw_get_motor(cfw_board* b, int side, int* ina, int* inb, int* pwm) {
  const chefbot::MotorOutput m = b->board.motor(side_of(side));
  if (ina) *ina = m.ina ? 1 : 0;
  if (inb) *inb = m.inb ? 1 : 0;
  if (pwm) *pwm = m.pwm;
}
double cfw_wheel_duty(cfw_board* b, int side) { return b->board.wheel_duty(side_of(side)); }
int32_t cfw_command(cfw_board* b, int side) { return b->board.firmware().command(side_of(side)); }
int cfw_drive_state(cfw_board* b) { return static_cast<int>(b->board.firmware().drive_state()); }

void cfw_encoder_edge(cfw_board* b, int side, int a, int b_level) {
  b->board.encoder_edge(side_of(side), a != 0, b_level != 0);
}
void cfw_encoder_step(cfw_board* b, int side, int32_t steps) { b->board.encoder_step(side_of(side), steps); }
void cfw_wheel_advance(cfw_board* b, int side, int32_t edges) { b->board.wheel_advance(side_of(side), edges); }
void cfw_set_encoder_count(cfw_board* b, int side, int32_t count) { b->board.set_encoder_count(side_of(side), count); }
int32_t cfw_encoder_count(cfw_board* b, int side) { return b->board.firmware().encoder(side_of(side)).count(); }

void cfw_set_ultrasonic_echo_us(cfw_board* b, int32_t us) { b->board.set_echo_us(us); }
void cfw_set_imu_quaternion(cfw_board* b, double x, double y, double z, double w) {
  chefbot::Quaternion q;
  q.x = static_cast<float>(x);
  q.y = static_cast<float>(y);
  q.z = static_cast<float>(z);
  q.w = static_cast<float>(w);
  b->board.set_imu(q);
}
void cfw_clear_imu(cfw_board* b) { b->board.clear_imu(); }
void cfw_set_battery_raw(cfw_board* b, uint16_t raw) { b->board.set_battery_raw(raw); }
void cfw_set_battery_volts(cfw_board* b, double volts) { b->board.set_battery_volts(volts); }

uint64_t cfw_stat(cfw_board* b, const char* name, int* found) {
  if (found) *found = 1;
  chefbot::Firmware& fw = b->board.firmware();
  const chefbot::RxStats& rx = fw.rx_stats();
  const chefbot::DiagCounters d = fw.diag(b->board.now());
  static const char kErrPrefix[] = "rx_error.";
  if (strncmp(name, kErrPrefix, sizeof(kErrPrefix) - 1) == 0) {
    const char* cls = name + sizeof(kErrPrefix) - 1;
    for (size_t i = 1; i < static_cast<size_t>(chefbot::RxError::Count); ++i) {
      if (strcmp(cls, chefbot::rx_error_name(static_cast<chefbot::RxError>(i))) == 0) return rx.errors[i];
    }
  }
  struct Entry {
    const char* name;
    uint64_t value;
  };
  const Entry entries[] = {
      {"rx_ok", rx.ok},
      {"rx_empty", rx.empty},
      {"rx_errors", rx.total_errors()},
      {"rx_overflow", b->board.rx_overflow()},
      {"watchdog_trips", d.watchdog_trips},
      {"encoder_illegal_left", d.encoder_illegal_left},
      {"encoder_illegal_right", d.encoder_illegal_right},
      {"tx_dropped_lines", d.tx_dropped_lines},
      {"tx_bytes", b->board.tx_bytes_total()},
      {"wire_overflow", b->board.wire_overflow()},
      {"schedule_overruns", d.schedule_overruns},
      {"status_cycles", fw.status_cycles()},
      {"resets", b->board.resets()},
      {"ultrasonic_triggers", b->board.triggers()},
      {"ultrasonic_cm", fw.ultrasonic().distance_cm()},
      {"battery_mv", fw.battery_mv()},
      {"imu_ok", d.imu_ok},
      {"elapsed_us", b->board.elapsed_us()},
  };
  for (const Entry& e : entries) {
    if (strcmp(name, e.name) == 0) return e.value;
  }
  if (found) *found = 0;
  return 0;
}

}  // extern "C"
