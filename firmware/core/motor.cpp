#include "motor.h"

namespace chefbot {

int32_t clamp_command(int32_t command, int32_t command_max) {
  if (command_max < 1) command_max = 1;
  if (command > command_max) return command_max;
  if (command < -command_max) return -command_max;
  return command;
}

uint8_t scale_to_pwm(int32_t command, const MotorMapping& m) {
  const int32_t max = m.command_max < 1 ? 1 : m.command_max;
  const int32_t c = clamp_command(command, max);
  const uint32_t mag = static_cast<uint32_t>(c < 0 ? -c : c);
  const uint32_t umax = static_cast<uint32_t>(max);
  return static_cast<uint8_t>((mag * m.pwm_max + umax / 2u) / umax);
}

MotorOutput motor_brake(const MotorMapping& m) {
  MotorOutput out;
  out.ina = false;
  out.inb = false;
  out.pwm = m.brake_pwm;
  return out;
}

MotorOutput motor_output(int32_t command, const MotorMapping& m) {
  if (command == 0) return motor_brake(m);
  bool clockwise = command > 0;
  if (m.invert) clockwise = !clockwise;
  MotorOutput out;
  out.ina = clockwise;
  out.inb = !clockwise;
  out.pwm = scale_to_pwm(command, m);
  return out;
}

}  // namespace chefbot
