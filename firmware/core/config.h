// Tunables of the firmware core, with the defaults that ship on the robot.
// Everything the PC side relies on (rates, timeouts, ranges) lives here so the
// board sketch, the host library and the tests agree on one set of numbers.
#ifndef CHEFBOT_CORE_CONFIG_H
#define CHEFBOT_CORE_CONFIG_H

#include <stdint.h>

namespace chefbot {

// Version of the serial protocol announced in the `v` line. Bump the number
// when a line changes meaning; adding trailing fields does not need a bump.
static const int32_t kProtocolVersion = 1;
static const char kFirmwareVersion[] = "chefbot_fw-1.0.0";

enum class EncoderMode : uint8_t {
  X4 = 4,  // every edge of A and B: 8400 counts per wheel revolution
  X2 = 2,  // every edge of A, direction from B: 4200 counts per revolution
  X1 = 1,  // rising edge of A only: 2100 counts per revolution
};

struct Config {
  // Status lines (`b t e u s i`) are emitted at this fixed rate. 30 Hz matches
  // the ChefBot PID rate, so every PID step sees fresh encoder counts, and
  // keeps the link under half of its capacity (see PROTOCOL.md, "Budget").
  uint32_t status_rate_hz = 30;
  // The diagnostics line `d` is sent once every this many status cycles.
  uint32_t diag_every_cycles = 30;
  // Motors brake when no valid `s` command arrived for this long.
  uint32_t watchdog_ms = 500;
  // `s` command arguments are clamped to +-command_max and mapped linearly
  // onto PWM 0..pwm_max (the book's PC side sends +-1023, the driver takes
  // 8-bit PWM).
  int32_t command_max = 1023;
  uint8_t pwm_max = 255;
  // PWM applied while braking. The VNH2SP30 only shorts the motor through its
  // low-side switches while PWM is high; PWM 0 with INA=INB=0 lets it coast.
  uint8_t brake_pwm = 255;
  // The right motor is mounted mirrored, so the same command must turn it the
  // other way to drive the robot forward.
  bool invert_left = false;
  bool invert_right = true;
  EncoderMode encoder_mode = EncoderMode::X4;
  bool invert_left_encoder = false;
  bool invert_right_encoder = true;
  // Append the `*HH` CRC-8 token to every board->PC line.
  bool tx_checksum = true;
  // HC-SR04: at least 60 ms between triggers (datasheet) so an old echo is
  // not taken for the new one; echoes longer than the 400 cm range are "no
  // echo".
  uint32_t ultrasonic_period_ms = 60;
  uint32_t ultrasonic_max_cm = 400;
  // Battery divider: Vbat -- R_top --+-- R_bottom -- GND, ADC at the middle.
  // 47k/10k maps 0..18.8 V onto the 0..3.3 V ADC range (12 V SLA or 3S LiPo).
  uint32_t battery_r_top_ohm = 47000;
  uint32_t battery_r_bottom_ohm = 10000;
  uint32_t adc_ref_mv = 3300;
  uint32_t adc_max_raw = 4095;  // TM4C123: 12-bit SAR ADC
  // Size of the board's UART transmit buffer and the line rate, used to pace
  // output instead of blocking inside Serial.write().
  uint32_t tx_buffer_bytes = 256;
  uint32_t tx_bytes_per_s = 11520;  // 115200 baud 8N1 = 10 bits per byte
};

}  // namespace chefbot

#endif
