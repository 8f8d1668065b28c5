// Non-blocking HC-SR04 ranging. The book used pulseIn(), which stalls the
// whole loop for up to a second without an echo; here the echo pin's edges
// are timestamped by an interrupt and the main loop only looks at the result.
//
// Cycle: trigger (10 us pulse, done by the HAL) -> wait for the echo to rise
// -> wait for it to fall -> distance = width_us / 29 / 2 cm (the book's
// formula; equal to width_us / 58 in integer arithmetic). Triggers are at
// least `period` apart (HC-SR04: >= 60 ms) so a late echo of the previous
// ping is not measured as the new one.
#ifndef CHEFBOT_CORE_ULTRASONIC_H
#define CHEFBOT_CORE_ULTRASONIC_H

#include <stdint.h>

namespace chefbot {

class UltrasonicRanger {
 public:
  // Reported when nothing came back within range (also what the book's
  // pulseIn() timeout produced: 0 cm).
  static const uint32_t kNoEcho = 0;
  // HC-SR04 cannot measure closer; nearer objects are reported at this value
  // rather than as 0, which would read as "nothing there".
  static const uint32_t kMinCm = 2;
  // The sensor starts its echo pulse a few hundred us after the trigger.
  static const uint32_t kRiseTimeoutUs = 10000;

  UltrasonicRanger(uint32_t period_us = 60000u, uint32_t max_cm = 400u);
  void configure(uint32_t period_us, uint32_t max_cm);
  void restart(uint32_t now_us);

  // Main loop. Returns true when the caller must fire the trigger pulse now.
  bool poll(uint32_t now_us);
  // From the echo pin interrupt (or the simulator), with the pin level after
  // the edge and its timestamp.
  void echo_edge(bool level, uint32_t t_us);

  uint32_t distance_cm() const { return distance_cm_; }
  uint32_t measurements() const { return measurements_; }
  uint32_t no_echoes() const { return no_echoes_; }
  static uint32_t width_to_cm(uint32_t width_us) { return width_us / 29u / 2u; }

 private:
  enum Phase : uint8_t { kIdle, kWaitRise, kWaitFall, kDone };
  void finish(uint32_t cm);

  uint32_t period_us_;
  uint32_t max_cm_;
  uint32_t max_width_us_;
  uint32_t last_trigger_us_ = 0;
  bool triggered_once_ = false;
  volatile uint8_t phase_ = kIdle;
  volatile uint32_t rise_us_ = 0;
  volatile uint32_t fall_us_ = 0;
  uint32_t distance_cm_ = kNoEcho;
  uint32_t measurements_ = 0;
  uint32_t no_echoes_ = 0;
};

}  // namespace chefbot

#endif
