#include "ultrasonic.h"

namespace chefbot {

UltrasonicRanger::UltrasonicRanger(uint32_t period_us, uint32_t max_cm) : period_us_(0), max_cm_(0), max_width_us_(0) {
  configure(period_us, max_cm);
}

void UltrasonicRanger::configure(uint32_t period_us, uint32_t max_cm) {
  // Below 60 ms the previous ping's echo can still be in the air.
  period_us_ = period_us < 60000u ? 60000u : period_us;
  // Three digits keep the `u` line within its budgeted length.
  max_cm_ = max_cm > 999u ? 999u : max_cm;
  // Widths just past max_cm still round down to max_cm; one more cm of slack.
  max_width_us_ = (max_cm_ + 1u) * 58u;
}

void UltrasonicRanger::restart(uint32_t now_us) {
  phase_ = kIdle;
  triggered_once_ = false;
  last_trigger_us_ = now_us;
  distance_cm_ = kNoEcho;
}

void UltrasonicRanger::finish(uint32_t cm) {
  distance_cm_ = cm;
  ++measurements_;
  if (cm == kNoEcho) ++no_echoes_;
  phase_ = kIdle;
}

bool UltrasonicRanger::poll(uint32_t now_us) {
  const uint8_t phase = phase_;
  if (phase == kDone) {
    const uint32_t width = fall_us_ - rise_us_;
    uint32_t cm = width_to_cm(width);
    if (width > max_width_us_ || cm > max_cm_) {
      cm = kNoEcho;
    } else if (cm < kMinCm) {
      cm = kMinCm;
    }
    finish(cm);
  } else if (phase == kWaitRise) {
    if (now_us - last_trigger_us_ > kRiseTimeoutUs) finish(kNoEcho);
  } else if (phase == kWaitFall) {
    if (now_us - rise_us_ > max_width_us_) finish(kNoEcho);
  }
  if (phase_ == kIdle && (!triggered_once_ || now_us - last_trigger_us_ >= period_us_)) {
    last_trigger_us_ = now_us;
    triggered_once_ = true;
    // Armed before the trigger so an echo edge can never find us idle.
    phase_ = kWaitRise;
    return true;
  }
  return false;
}

void UltrasonicRanger::echo_edge(bool level, uint32_t t_us) {
  const uint8_t phase = phase_;
  if (level && phase == kWaitRise) {
    rise_us_ = t_us;
    phase_ = kWaitFall;
  } else if (!level && phase == kWaitFall) {
    fall_us_ = t_us;
    phase_ = kDone;
  }
}

}  // namespace chefbot

// Out-of-line definitions: C++11 needs them when the constants are odr-used.
const uint32_t chefbot::UltrasonicRanger::kNoEcho;
const uint32_t chefbot::UltrasonicRanger::kMinCm;
const uint32_t chefbot::UltrasonicRanger::kRiseTimeoutUs;
