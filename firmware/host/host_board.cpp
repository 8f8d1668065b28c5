#include "host_board.h"

namespace chefbot {
namespace host {

namespace {
// Gray-code order of (A << 1) | B when moving forward: 00 01 11 10.
const uint8_t kGray[4] = {0, 1, 3, 2};

int gray_index(uint8_t state) {
  for (int i = 0; i < 4; ++i)
    if (kGray[i] == state) return i;
  return 0;
}

bool reached(uint32_t now, uint32_t at) { return static_cast<int32_t>(now - at) >= 0; }
}  // namespace

HostBoard::HostBoard(const Config& cfg) : cfg_(cfg) {
  set_battery_volts(12.6);
  power_on();
}

HostBoard::~HostBoard() { delete fw_; }

void HostBoard::power_on() {
  delete fw_;
  Hal hal;
  hal.clock = this;
  hal.serial = this;
  hal.motors = this;
  hal.encoders = nullptr;
  hal.ultrasonic = this;
  hal.imu = this;
  hal.battery = this;
  hal.reset = this;
  fw_ = new Firmware(hal, cfg_);
  // A reset loses whatever the UARTs held.
  rx_.clear();
  uart_.clear();
  tx_credit_ = 0;
  echo_pending_rise_ = echo_pending_fall_ = false;
  reset_pending_ = false;
  power_on_triggers_ = 0;
  fw_->begin();
  for (int s = 0; s < 2; ++s) {
    fw_->encoder_prime(static_cast<Side>(s), (pins_[s] & 2u) != 0, (pins_[s] & 1u) != 0);
  }
}

size_t HostBoard::feed(const uint8_t* data, size_t len) {
  size_t n = 0;
  for (; n < len; ++n) {
    if (rx_.size() >= kRxBufferBytes) {
      rx_overflow_ += static_cast<uint32_t>(len - n);
      break;
    }
    rx_.push_back(data[n]);
  }
  return n;
}

int HostBoard::read_byte() {
  if (rx_.empty()) return -1;
  const uint8_t c = rx_.front();
  rx_.pop_front();
  return c;
}

size_t HostBoard::tx_space() {
  const size_t cap = fw_ ? fw_->config().tx_buffer_bytes : cfg_.tx_buffer_bytes;
  if (instant_tx_) return cap;
  return uart_.size() >= cap ? 0 : cap - uart_.size();
}

void HostBoard::write(const char* data, size_t len) {
  for (size_t i = 0; i < len; ++i) {
    if (instant_tx_) {
      if (wire_.size() < kWireBufferBytes) {
        wire_.push_back(static_cast<uint8_t>(data[i]));
      } else {
        ++wire_overflow_;
      }
      ++tx_total_;
    } else {
      uart_.push_back(static_cast<uint8_t>(data[i]));
    }
  }
}

void HostBoard::drain_uart(uint32_t dt) {
  if (uart_.empty()) {
    tx_credit_ = 0;  // an idle UART does not bank time
    return;
  }
  const uint64_t bps = fw_->config().tx_bytes_per_s;
  tx_credit_ += static_cast<uint64_t>(dt) * bps;
  while (!uart_.empty() && tx_credit_ >= 1000000u) {
    tx_credit_ -= 1000000u;
    if (wire_.size() < kWireBufferBytes) {
      wire_.push_back(uart_.front());
    } else {
      ++wire_overflow_;
    }
    uart_.pop_front();
    ++tx_total_;
  }
  if (uart_.empty()) tx_credit_ = 0;
}

size_t HostBoard::read_tx(uint8_t* out, size_t max) {
  size_t n = 0;
  while (n < max && !wire_.empty()) {
    out[n++] = wire_.front();
    wire_.pop_front();
  }
  return n;
}

std::string HostBoard::read_tx_string() {
  std::string s(wire_.begin(), wire_.end());
  wire_.clear();
  return s;
}

void HostBoard::apply(Side side, const MotorOutput& out) { motors_[side & 1] = out; }

double HostBoard::wheel_duty(Side side) const {
  const MotorOutput& m = motors_[side & 1];
  if (m.ina == m.inb) return 0.0;  // either brake
  const Config& c = fw_->config();
  double d = static_cast<double>(m.pwm) / (c.pwm_max ? c.pwm_max : 1);
  if (m.inb) d = -d;
  const bool invert = (side & 1) ? c.invert_right : c.invert_left;
  return invert ? -d : d;
}

void HostBoard::trigger() {
  ++triggers_;
  ++power_on_triggers_;
  last_trigger_us_ = now_;
  if (echo_us_ > 0) {
    echo_rise_at_ = now_ + 10u + kEchoDelayUs;
    echo_fall_at_ = echo_rise_at_ + static_cast<uint32_t>(echo_us_);
    echo_pending_rise_ = echo_pending_fall_ = true;
  }
}

void HostBoard::deliver_echo_edges() {
  if (echo_pending_rise_ && reached(now_, echo_rise_at_)) {
    echo_pending_rise_ = false;
    fw_->echo_edge(true, echo_rise_at_);
  }
  if (!echo_pending_rise_ && echo_pending_fall_ && reached(now_, echo_fall_at_)) {
    echo_pending_fall_ = false;
    fw_->echo_edge(false, echo_fall_at_);
  }
}

void HostBoard::set_imu(const Quaternion& q) {
  imu_q_ = q;
  if (!imu_present_) imu_last_us_ = now_ - kImuPeriodUs;
  imu_present_ = true;
}

bool HostBoard::poll(Quaternion& q) {
  if (!imu_present_ || now_ - imu_last_us_ < kImuPeriodUs) return false;
  imu_last_us_ = now_;
  q = imu_q_;
  return true;
}

void HostBoard::set_battery_volts(double volts) {
  const Config& c = fw_ ? fw_->config() : cfg_;
  const double ratio = static_cast<double>(c.battery_r_top_ohm + c.battery_r_bottom_ohm) / c.battery_r_bottom_ohm;
  double raw = volts / ratio / (c.adc_ref_mv / 1000.0) * c.adc_max_raw + 0.5;
  if (raw < 0) raw = 0;
  if (raw > c.adc_max_raw) raw = c.adc_max_raw;
  battery_raw_ = static_cast<uint16_t>(raw);
}

void HostBoard::encoder_edge(Side side, bool a, bool b) {
  pins_[side & 1] = static_cast<uint8_t>((a ? 2u : 0u) | (b ? 1u : 0u));
  fw_->encoder_edge(side, a, b);
}

void HostBoard::encoder_step(Side side, int32_t steps) {
  const int s = side & 1;
  int idx = gray_index(pins_[s]);
  const int dir = steps < 0 ? -1 : 1;
  uint32_t n = steps < 0 ? 0u - static_cast<uint32_t>(steps) : static_cast<uint32_t>(steps);
  for (; n > 0; --n) {
    idx = (idx + dir + 4) & 3;
    encoder_edge(side, (kGray[idx] & 2u) != 0, (kGray[idx] & 1u) != 0);
  }
}

void HostBoard::wheel_advance(Side side, int32_t edges) {
  const Config& c = fw_->config();
  const bool invert = (side & 1) ? c.invert_right_encoder : c.invert_left_encoder;
  encoder_step(side, invert ? -edges : edges);
}

void HostBoard::set_encoder_count(Side side, int32_t count) { fw_->encoder(side).set_count(count); }

void HostBoard::poll_once() {
  deliver_echo_edges();
  fw_->poll();
  if (reset_pending_) {
    ++resets_;
    power_on();
  }
}

void HostBoard::step_time(uint32_t dt) {
  now_ += dt;
  elapsed_ += dt;
  if (!instant_tx_) drain_uart(dt);
}

void HostBoard::advance(uint64_t us) {
  while (us > 0) {
    const uint32_t dt = us < loop_us_ ? static_cast<uint32_t>(us) : loop_us_;
    step_time(dt);
    us -= dt;
    poll_once();
  }
}

}  // namespace host
}  // namespace chefbot

const uint32_t chefbot::host::HostBoard::kEchoDelayUs;
const uint32_t chefbot::host::HostBoard::kImuPeriodUs;
const size_t chefbot::host::HostBoard::kRxBufferBytes;
const size_t chefbot::host::HostBoard::kWireBufferBytes;
