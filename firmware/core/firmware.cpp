#include "firmware.h"

namespace chefbot {

namespace {

uint32_t clamp_u32(uint32_t v, uint32_t lo, uint32_t hi) { return v < lo ? lo : (v > hi ? hi : v); }

bool plausible(const Quaternion& q) {
  const float c[4] = {q.x, q.y, q.z, q.w};
  float norm2 = 0.0f;
  for (int i = 0; i < 4; ++i) {
    if (!(c[i] == c[i])) return false;  // NaN
    if (c[i] > 1.01f || c[i] < -1.01f) return false;
    norm2 += c[i] * c[i];
  }
  // The DMP emits unit quaternions; anything far off is a corrupt I2C read.
  return norm2 > 0.8f && norm2 < 1.2f;
}

}  // namespace

Config sanitize(const Config& in) {
  Config c = in;
  c.status_rate_hz = clamp_u32(c.status_rate_hz, 1u, 200u);
  c.watchdog_ms = clamp_u32(c.watchdog_ms, 20u, 60000u);
  // Four digits keep the `s` echo inside its budgeted length.
  if (c.command_max < 1) c.command_max = 1;
  if (c.command_max > 9999) c.command_max = 9999;
  if (c.encoder_mode != EncoderMode::X4 && c.encoder_mode != EncoderMode::X2 && c.encoder_mode != EncoderMode::X1) {
    c.encoder_mode = EncoderMode::X4;
  }
  c.ultrasonic_period_ms = clamp_u32(c.ultrasonic_period_ms, 60u, 10000u);
  c.ultrasonic_max_cm = clamp_u32(c.ultrasonic_max_cm, 2u, 999u);
  if (c.battery_r_bottom_ohm == 0) c.battery_r_bottom_ohm = 1;
  if (c.adc_max_raw == 0) c.adc_max_raw = 1;
  c.tx_buffer_bytes = clamp_u32(c.tx_buffer_bytes, 16u, 65536u);
  c.tx_bytes_per_s = clamp_u32(c.tx_bytes_per_s, 100u, 40000u);
  return c;
}

Firmware::Firmware(const Hal& hal, const Config& cfg)
    : hal_(hal), cfg_(sanitize(cfg)), parser_(cfg_.command_max), command_(), applied_() {}

void Firmware::begin() {
  for (int s = 0; s < 2; ++s) {
    mapping_[s].command_max = cfg_.command_max;
    mapping_[s].pwm_max = cfg_.pwm_max;
    mapping_[s].brake_pwm = cfg_.brake_pwm;
  }
  mapping_[kLeft].invert = cfg_.invert_left;
  mapping_[kRight].invert = cfg_.invert_right;
  decoder_[kLeft].configure(cfg_.encoder_mode, cfg_.invert_left_encoder);
  decoder_[kRight].configure(cfg_.encoder_mode, cfg_.invert_right_encoder);
  decoder_[kLeft].set_count(0);
  decoder_[kRight].set_count(0);

  parser_ = CommandParser(cfg_.command_max);
  watchdog_ = CommandWatchdog(cfg_.watchdog_ms * 1000u);
  command_[kLeft] = command_[kRight] = 0;
  apply_motors(true);

  const uint32_t now = hal_.clock->micros();
  ranger_.configure(cfg_.ultrasonic_period_ms * 1000u, cfg_.ultrasonic_max_cm);
  ranger_.restart(now);
  BatteryDivider div;
  div.r_top_ohm = cfg_.battery_r_top_ohm;
  div.r_bottom_ohm = cfg_.battery_r_bottom_ohm;
  div.adc_ref_mv = cfg_.adc_ref_mv;
  div.adc_max_raw = cfg_.adc_max_raw;
  battery_.configure(div);
  battery_.reset();
  imu_have_ = false;
  imu_rejected_ = 0;
  tx_dropped_ = 0;

  if (hal_.encoders) hal_.encoders->begin(*this);
  if (hal_.ultrasonic) hal_.ultrasonic->begin(*this);

  // The leading '\n' ends whatever line the reset cut short on the PC side,
  // so the hello line itself arrives intact (parsers skip blank lines).
  if (hal_.serial->tx_space() >= 1) hal_.serial->write("\n", 1);
  send(format_hello(line_, cfg_, cfg_.tx_checksum));
  scheduler_ = PeriodicScheduler(1000000u / cfg_.status_rate_hz);
  scheduler_.start(now);
}

void Firmware::encoder_prime(Side side, bool a, bool b) { decoder_[side & 1].prime(a, b); }

void Firmware::encoder_edge(Side side, bool a, bool b) { decoder_[side & 1].update(a, b); }

void Firmware::echo_edge(bool level, uint32_t t_us) { ranger_.echo_edge(level, t_us); }

void Firmware::set_commands(int32_t left, int32_t right) {
  command_[kLeft] = clamp_command(left, cfg_.command_max);
  command_[kRight] = clamp_command(right, cfg_.command_max);
}

void Firmware::apply_motors(bool force) {
  for (int s = 0; s < 2; ++s) {
    const MotorOutput out =
        watchdog_.motors_enabled() ? motor_output(command_[s], mapping_[s]) : motor_brake(mapping_[s]);
    // Only on change: re-writing PWM every pass restarts the timer period on
    // some cores and makes the motor whine.
    if (force || !(out == applied_[s])) {
      applied_[s] = out;
      hal_.motors->apply(static_cast<Side>(s), out);
    }
  }
}

void Firmware::handle(const Command& cmd, uint32_t now_us) {
  if (cmd.event == RxEvent::Speed) {
    set_commands(cmd.left, cmd.right);
    watchdog_.feed(now_us);
    apply_motors(false);
  } else if (cmd.event == RxEvent::Reset) {
    // Stop first: the board may take a while to come back from reset.
    watchdog_.stop();
    set_commands(0, 0);
    apply_motors(false);
    if (hal_.reset) {
      hal_.reset->reset_board();
    } else {
      begin();
    }
  }
}

void Firmware::poll() {
  uint32_t now = hal_.clock->micros();
  for (int i = 0; i < kMaxRxBytesPerPoll; ++i) {
    const int c = hal_.serial->read_byte();
    if (c < 0) break;
    Command cmd;
    if (parser_.push(static_cast<uint8_t>(c), cmd) != RxEvent::None) {
      handle(cmd, now);
      if (cmd.event == RxEvent::Reset) return;  // state was re-initialised
    }
  }

  if (watchdog_.check(now)) {
    set_commands(0, 0);
    apply_motors(false);
  }

  if (hal_.ultrasonic && ranger_.poll(now)) hal_.ultrasonic->trigger();

  if (hal_.imu) {
    Quaternion q;
    if (hal_.imu->poll(q)) {
      if (plausible(q)) {
        imu_q_ = q;
        imu_have_ = true;
        imu_last_us_ = now;
      } else {
        ++imu_rejected_;
      }
    }
  }

  now = hal_.clock->micros();
  if (scheduler_.due(now)) emit_status(now);
}

bool Firmware::imu_fresh(uint32_t now_us) const { return imu_have_ && now_us - imu_last_us_ <= kImuStaleUs; }

DiagCounters Firmware::diag(uint32_t now_us) const {
  DiagCounters d;
  d.rx_ok = parser_.stats().ok;
  d.rx_errors = parser_.stats().total_errors();
  d.watchdog_trips = watchdog_.trips();
  d.encoder_illegal_left = decoder_[kLeft].illegal();
  d.encoder_illegal_right = decoder_[kRight].illegal();
  d.tx_dropped_lines = tx_dropped_;
  d.schedule_overruns = scheduler_.overruns();
  d.imu_ok = imu_fresh(now_us) ? 1u : 0u;
  return d;
}

void Firmware::send(size_t len) {
  if (len == 0) return;
  if (hal_.serial->tx_space() < len) {
    ++tx_dropped_;
    return;
  }
  hal_.serial->write(line_.data(), len);
}

void Firmware::emit_status(uint32_t now_us) {
  const bool crc = cfg_.tx_checksum;
  // The book's order: time, encoders, ultrasonic, motor echo, IMU, battery.
  send(format_time(line_, now_us, scheduler_.last_interval_us(), crc));
  send(format_encoders(line_, decoder_[kLeft].count(), decoder_[kRight].count(), crc));
  if (hal_.ultrasonic) send(format_ultrasonic(line_, ranger_.distance_cm(), crc));
  send(format_speed(line_, command_[kLeft], command_[kRight], watchdog_.state(), crc));
  if (imu_fresh(now_us)) send(format_imu(line_, imu_q_, crc));
  if (hal_.battery) {
    battery_.sample(hal_.battery->read_raw());
    send(format_battery(line_, battery_.millivolts(), crc));
  }
  if (cfg_.diag_every_cycles > 0 && scheduler_.cycles() % cfg_.diag_every_cycles == 0) {
    send(format_diag(line_, diag(now_us), crc));
  }
}

}  // namespace chefbot

// Out-of-line definitions: C++11 needs them when the constants are odr-used.
const int chefbot::Firmware::kMaxRxBytesPerPoll;
const uint32_t chefbot::Firmware::kImuStaleUs;
