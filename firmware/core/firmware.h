// The whole board behaviour, independent of the board: command parsing,
// watchdog, motor mapping, encoder decoding, ultrasonic ranging, battery
// and IMU sampling, and fixed-rate status output. The Energia sketch and the
// host library only construct it with a Hal and call begin() once and poll()
// as often as they can; interrupts call encoder_edge()/echo_edge().
//
// No heap, no exceptions, bounded work per poll().
#ifndef CHEFBOT_CORE_FIRMWARE_H
#define CHEFBOT_CORE_FIRMWARE_H

#include <stdint.h>

#include "../hal/hal.h"
#include "battery.h"
#include "command_parser.h"
#include "config.h"
#include "line_format.h"
#include "motor.h"
#include "quadrature.h"
#include "scheduler.h"
#include "ultrasonic.h"
#include "watchdog.h"

namespace chefbot {

// Clamps every field into the range the rest of the core (and the serial
// budget, and the fixed line lengths) assumes.
Config sanitize(const Config& cfg);

class Firmware final : public EncoderSink, public EchoSink {
 public:
  // Bytes taken from the serial port per poll(): keeps a poll() bounded even
  // when the PC floods the link; the UART buffer holds the rest.
  static const int kMaxRxBytesPerPoll = 64;
  // The `i` line stops when the IMU has been silent this long, rather than
  // repeating a stale orientation.
  static const uint32_t kImuStaleUs = 1000000u;

  Firmware(const Hal& hal, const Config& cfg);

  // Power-up state: motors braked, counters cleared, `v` line sent.
  void begin();
  void poll();

  void encoder_prime(Side side, bool a, bool b) override;
  void encoder_edge(Side side, bool a, bool b) override;
  void echo_edge(bool level, uint32_t t_us) override;

  // Inspection (tests, host library).
  const Config& config() const { return cfg_; }
  const MotorOutput& motor(Side side) const { return applied_[side]; }
  int32_t command(Side side) const { return command_[side]; }
  DriveState drive_state() const { return watchdog_.state(); }
  const RxStats& rx_stats() const { return parser_.stats(); }
  QuadratureDecoder& encoder(Side side) { return decoder_[side]; }
  const UltrasonicRanger& ultrasonic() const { return ranger_; }
  const PeriodicScheduler& scheduler() const { return scheduler_; }
  DiagCounters diag(uint32_t now_us) const;
  uint32_t battery_mv() const { return battery_.millivolts(); }
  uint32_t tx_dropped_lines() const { return tx_dropped_; }
  uint32_t status_cycles() const { return scheduler_.cycles(); }

 private:
  void handle(const Command& cmd, uint32_t now_us);
  void set_commands(int32_t left, int32_t right);
  void apply_motors(bool force);
  void emit_status(uint32_t now_us);
  void send(size_t len);
  bool imu_fresh(uint32_t now_us) const;

  Hal hal_;
  Config cfg_;
  MotorMapping mapping_[2];
  CommandParser parser_;
  CommandWatchdog watchdog_;
  QuadratureDecoder decoder_[2];
  UltrasonicRanger ranger_;
  BatteryMonitor battery_;
  PeriodicScheduler scheduler_;
  LineBuilder line_;
  int32_t command_[2];
  MotorOutput applied_[2];
  Quaternion imu_q_;
  bool imu_have_ = false;
  uint32_t imu_last_us_ = 0;
  uint32_t imu_rejected_ = 0;
  uint32_t tx_dropped_ = 0;
};

}  // namespace chefbot

#endif
