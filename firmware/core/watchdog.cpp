#include "watchdog.h"

namespace chefbot {

void CommandWatchdog::feed(uint32_t now_us) {
  last_feed_us_ = now_us;
  state_ = DriveState::Run;
}

bool CommandWatchdog::check(uint32_t now_us) {
  if (state_ != DriveState::Run) return false;
  if (now_us - last_feed_us_ < timeout_us_) return false;
  state_ = DriveState::Timeout;
  ++trips_;
  return true;
}

void CommandWatchdog::stop() { state_ = DriveState::Idle; }

}  // namespace chefbot
