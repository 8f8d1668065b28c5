// Signed speed command -> VNH2SP30 inputs (INA, INB, PWM) for one motor.
//
// Truth table (VNH2SP30 datasheet, DIAG/EN pulled high):
//   INA=1 INB=0 -> clockwise         INA=0 INB=1 -> counter-clockwise
//   INA=1 INB=1 -> brake to Vcc      INA=0 INB=0 -> brake to GND
// Positive commands map to clockwise (before inversion). Zero, and every
// stop the core decides on (watchdog, reset, idle), brakes to GND with
// brake_pwm: the low-side switches only conduct while PWM is high.
#ifndef CHEFBOT_CORE_MOTOR_H
#define CHEFBOT_CORE_MOTOR_H

#include <stdint.h>

namespace chefbot {

struct MotorOutput {
  bool ina = false;
  bool inb = false;
  uint8_t pwm = 0;
  bool operator==(const MotorOutput& o) const { return ina == o.ina && inb == o.inb && pwm == o.pwm; }
};

struct MotorMapping {
  int32_t command_max = 1023;  // |command| at and beyond which PWM is pwm_max
  uint8_t pwm_max = 255;
  uint8_t brake_pwm = 255;
  bool invert = false;  // motor mounted mirrored: swap directions
};

// Clamps command to +-command_max.
int32_t clamp_command(int32_t command, int32_t command_max);

// Rounded linear scaling |command| * pwm_max / command_max, so +-1023 gives
// 255 and +-512 gives 128 (truncating would lose the top step).
uint8_t scale_to_pwm(int32_t command, const MotorMapping& m);

MotorOutput motor_output(int32_t command, const MotorMapping& m);
MotorOutput motor_brake(const MotorMapping& m);

}  // namespace chefbot

#endif
