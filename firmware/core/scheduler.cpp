#include "scheduler.h"

namespace chefbot {

void PeriodicScheduler::start(uint32_t now_us) {
  next_us_ = now_us;
  last_start_us_ = now_us;
  last_interval_us_ = 0;
  cycles_ = 0;
}

bool PeriodicScheduler::due(uint32_t now_us) {
  // Signed view of the distance to the deadline: correct across the 2^32 us
  // wrap as long as the loop runs more often than every 35 minutes.
  const int32_t late = static_cast<int32_t>(now_us - next_us_);
  if (late < 0) return false;
  if (static_cast<uint32_t>(late) >= period_us_) {
    overruns_ += static_cast<uint32_t>(late) / period_us_;
    next_us_ = now_us + period_us_;
  } else {
    next_us_ += period_us_;
  }
  if (cycles_ > 0) last_interval_us_ = now_us - last_start_us_;
  last_start_us_ = now_us;
  ++cycles_;
  return true;
}

void TxPacer::configure(uint32_t buffer_bytes, uint32_t bytes_per_s) {
  buffer_bytes_ = buffer_bytes;
  bytes_per_s_ = bytes_per_s < 1u ? 1u : (bytes_per_s > 40000u ? 40000u : bytes_per_s);
  queued_ = 0;
}

void TxPacer::drain(uint32_t now_us) {
  uint32_t elapsed = now_us - last_us_;
  last_us_ = now_us;
  if (queued_ == 0) {
    carry_us_ = 0;
    return;
  }
  // Clamped so the products stay in 32 bits (no 64-bit division helpers on
  // the board); a longer gap only under-estimates the drain, i.e. errs safe.
  if (elapsed > 100000u) elapsed = 100000u;
  const uint32_t total = elapsed + carry_us_;
  const uint32_t sent = total * bytes_per_s_ / 1000000u;
  if (sent >= queued_) {
    queued_ = 0;
    carry_us_ = 0;
  } else {
    queued_ -= sent;
    carry_us_ = total - sent * 1000000u / bytes_per_s_;
  }
}

uint32_t TxPacer::space(uint32_t now_us) {
  drain(now_us);
  return queued_ >= buffer_bytes_ ? 0u : buffer_bytes_ - queued_;
}

void TxPacer::wrote(uint32_t n, uint32_t now_us) {
  drain(now_us);
  queued_ += n;
}

}  // namespace chefbot
