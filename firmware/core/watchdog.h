// Command watchdog: the motors may only run while valid `s` commands keep
// arriving. The book's firmware kept the last speed forever when the PC
// died; here the drive stops `timeout` after the last command and stays
// stopped until the next valid command.
#ifndef CHEFBOT_CORE_WATCHDOG_H
#define CHEFBOT_CORE_WATCHDOG_H

#include <stdint.h>

#include "line_format.h"

namespace chefbot {

class CommandWatchdog {
 public:
  explicit CommandWatchdog(uint32_t timeout_us = 500000u) : timeout_us_(timeout_us) {}

  void set_timeout_us(uint32_t t) { timeout_us_ = t; }
  void feed(uint32_t now_us);
  // Returns true exactly once per trip (the moment the timeout is reached).
  // Time differences are unsigned, so micros() wrapping after 71 min is fine.
  bool check(uint32_t now_us);
  void stop();  // back to Idle (reset)

  DriveState state() const { return state_; }
  bool motors_enabled() const { return state_ == DriveState::Run; }
  uint32_t trips() const { return trips_; }

 private:
  uint32_t timeout_us_;
  uint32_t last_feed_us_ = 0;
  uint32_t trips_ = 0;
  DriveState state_ = DriveState::Idle;
};

}  // namespace chefbot

#endif
