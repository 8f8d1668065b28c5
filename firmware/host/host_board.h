// In-memory board for the host: implements the HAL with a simulated clock,
// a UART that drains at the real line rate, an HC-SR04 that answers triggers
// with echo edges at the right times, a DMP-like IMU stream and an ADC. Used
// by the unit tests, the fuzzer and (through the C API) the simulator.
#ifndef CHEFBOT_HOST_HOST_BOARD_H
#define CHEFBOT_HOST_HOST_BOARD_H

#include <stddef.h>
#include <stdint.h>

#include <deque>
#include <string>

#include "../core/firmware.h"

namespace chefbot {
namespace host {

class HostBoard final : Clock, SerialPort, MotorPins, UltrasonicPins, ImuSource, AnalogInput, ResetLine {
 public:
  // HC-SR04: delay between the end of the trigger and the echo going high
  // (8-cycle 40 kHz burst plus set-up).
  static const uint32_t kEchoDelayUs = 460;
  // DMP FIFO rate used by the book's sketch.
  static const uint32_t kImuPeriodUs = 10000;

  explicit HostBoard(const Config& cfg = Config());
  ~HostBoard();

  Config& config() { return cfg_; }
  // Power-on (or hardware reset): a fresh core with the current config.
  void power_on();

  // PC -> board bytes; returns how many fit in the RX buffer.
  size_t feed(const uint8_t* data, size_t len);
  // Runs the board for `us` microseconds of simulated time, one main-loop
  // pass every loop_us.
  void advance(uint64_t us);
  void poll_once();
  void set_loop_us(uint32_t us) { loop_us_ = us ? us : 1; }
  // Board -> PC bytes that have left the UART.
  size_t read_tx(uint8_t* out, size_t max);
  std::string read_tx_string();
  size_t tx_available() const { return wire_.size(); }
  // Skips the line-rate model: everything written appears on the wire at once.
  void set_instant_tx(bool on) { instant_tx_ = on; }

  // Sensors.
  void encoder_edge(Side side, bool a, bool b);
  void encoder_step(Side side, int32_t steps);  // Gray-code steps at the pins
  void wheel_advance(Side side, int32_t edges);  // forward = robot forward
  void set_encoder_count(Side side, int32_t count);
  void set_echo_us(int32_t us) { echo_us_ = us; }
  void set_imu(const Quaternion& q);
  void clear_imu() { imu_present_ = false; }
  void set_battery_raw(uint16_t raw) { battery_raw_ = raw; }
  void set_battery_volts(double volts);
  void set_clock(uint32_t us) { now_ = us; }

  // Outputs and state.
  Firmware& firmware() { return *fw_; }
  MotorOutput motor(Side side) const { return motors_[side]; }
  double wheel_duty(Side side) const;  // [-1, 1], robot-forward convention
  uint32_t now() const { return now_; }
  uint64_t elapsed_us() const { return elapsed_; }
  uint32_t resets() const { return resets_; }
  uint32_t triggers() const { return triggers_; }
  uint32_t triggers_since_power_on() const { return power_on_triggers_; }
  uint32_t last_trigger_us() const { return last_trigger_us_; }
  uint32_t rx_overflow() const { return rx_overflow_; }
  size_t rx_pending() const { return rx_.size(); }
  uint32_t wire_overflow() const { return wire_overflow_; }
  uint64_t tx_bytes_total() const { return tx_total_; }
  size_t tx_queued() const { return uart_.size(); }

  static const size_t kRxBufferBytes = 4096;
  static const size_t kWireBufferBytes = 1u << 20;

 private:
  // HAL
  uint32_t micros() override { return now_; }
  int read_byte() override;
  size_t tx_space() override;
  void write(const char* data, size_t len) override;
  void apply(Side side, const MotorOutput& out) override;
  void begin(EchoSink& sink) override { (void)sink; }
  void trigger() override;
  bool poll(Quaternion& q) override;
  uint16_t read_raw() override { return battery_raw_; }
  void reset_board() override { reset_pending_ = true; }

  void step_time(uint32_t dt);
  void deliver_echo_edges();
  void drain_uart(uint32_t dt);

  Config cfg_;
  Firmware* fw_ = nullptr;
  uint32_t now_ = 0;
  uint64_t elapsed_ = 0;
  uint32_t loop_us_ = 200;
  std::deque<uint8_t> rx_;
  std::deque<uint8_t> uart_;
  std::deque<uint8_t> wire_;
  bool instant_tx_ = false;
  uint64_t tx_credit_ = 0;  // byte-time credit in us * bytes_per_s
  uint64_t tx_total_ = 0;
  uint32_t rx_overflow_ = 0;
  uint32_t wire_overflow_ = 0;
  MotorOutput motors_[2];
  uint8_t pins_[2] = {0, 0};
  int32_t echo_us_ = 0;
  bool echo_pending_rise_ = false;
  bool echo_pending_fall_ = false;
  uint32_t echo_rise_at_ = 0;
  uint32_t echo_fall_at_ = 0;
  uint32_t triggers_ = 0;
  uint32_t power_on_triggers_ = 0;
  uint32_t last_trigger_us_ = 0;
  Quaternion imu_q_;
  bool imu_present_ = false;
  uint32_t imu_last_us_ = 0;
  uint16_t battery_raw_ = 0;
  bool reset_pending_ = false;
  uint32_t resets_ = 0;
};

}  // namespace host
}  // namespace chefbot

#endif
