// Fixed-rate scheduling for the status lines. The book printed them on every
// loop pass, so the rate depended on how long pulseIn() and I2C took; here a
// cycle starts every `period` on a fixed grid (no drift from loop jitter).
// If the loop falls more than a whole period behind, the missed cycles are
// dropped (counted as overruns) instead of being sent in a burst.
#ifndef CHEFBOT_CORE_SCHEDULER_H
#define CHEFBOT_CORE_SCHEDULER_H

#include <stdint.h>

namespace chefbot {

class PeriodicScheduler {
 public:
  explicit PeriodicScheduler(uint32_t period_us = 33333u) : period_us_(period_us ? period_us : 1u) {}

  void set_period_us(uint32_t p) { period_us_ = p ? p : 1u; }
  uint32_t period_us() const { return period_us_; }
  // The first cycle is due immediately.
  void start(uint32_t now_us);
  // True once per period. Time differences are unsigned (micros() wraps).
  bool due(uint32_t now_us);
  // Time between the starts of the last two cycles (0 before the second).
  uint32_t last_interval_us() const { return last_interval_us_; }
  uint32_t overruns() const { return overruns_; }
  uint32_t cycles() const { return cycles_; }

 private:
  uint32_t period_us_;
  uint32_t next_us_ = 0;
  uint32_t last_start_us_ = 0;
  uint32_t last_interval_us_ = 0;
  uint32_t overruns_ = 0;
  uint32_t cycles_ = 0;
};

// Estimate of the UART transmit buffer fill: it drains at the line rate. The
// core asks for room before writing a line and skips the line when there is
// none, so Serial.write() never blocks the loop (and the watchdog with it).
class TxPacer {
 public:
  TxPacer(uint32_t buffer_bytes = 256u, uint32_t bytes_per_s = 11520u) : buffer_bytes_(0), bytes_per_s_(1) {
    configure(buffer_bytes, bytes_per_s);
  }
  void configure(uint32_t buffer_bytes, uint32_t bytes_per_s);
  uint32_t space(uint32_t now_us);
  void wrote(uint32_t n, uint32_t now_us);

 private:
  void drain(uint32_t now_us);
  uint32_t buffer_bytes_;
  uint32_t bytes_per_s_;
  uint32_t queued_ = 0;
  uint32_t last_us_ = 0;
  uint32_t carry_us_ = 0;
};

}  // namespace chefbot

#endif
