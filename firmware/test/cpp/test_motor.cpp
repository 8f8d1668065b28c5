#include <doctest/doctest.h>

#include "../../core/motor.h"

using namespace chefbot;

TEST_CASE("motor: VNH2SP30 truth table") {
  MotorMapping m;
  const MotorOutput cw = motor_output(500, m);
  CHECK(cw.ina);
  CHECK_FALSE(cw.inb);
  const MotorOutput ccw = motor_output(-500, m);
  CHECK_FALSE(ccw.ina);
  CHECK(ccw.inb);
  const MotorOutput stop = motor_output(0, m);
  CHECK_FALSE(stop.ina);  // brake to GND
  CHECK_FALSE(stop.inb);
  CHECK(stop.pwm == 255);  // low sides only conduct with PWM high
  CHECK(motor_brake(m) == stop);
  // Brake to Vcc (INA=INB=1) is never produced.
  for (int c = -1100; c <= 1100; ++c) {
    const MotorOutput o = motor_output(c, m);
    CHECK_FALSE((o.ina && o.inb));
  }
}

TEST_CASE("motor: inversion swaps direction, not brake") {
  MotorMapping m;
  m.invert = true;
  const MotorOutput o = motor_output(500, m);
  CHECK_FALSE(o.ina);
  CHECK(o.inb);
  CHECK(motor_output(-500, m).ina);
  CHECK(motor_output(0, m) == motor_brake(m));
}

TEST_CASE("motor: scaling is rounded, monotonic and clamped") {
  MotorMapping m;  // +-1023 -> 0..255
  CHECK(scale_to_pwm(1023, m) == 255);
  CHECK(scale_to_pwm(-1023, m) == 255);
  CHECK(scale_to_pwm(512, m) == 128);
  CHECK(scale_to_pwm(1, m) == 0);
  CHECK(scale_to_pwm(2, m) == 0);
  CHECK(scale_to_pwm(3, m) == 1);  // 0.748 rounds up: truncation would give 0
  CHECK(scale_to_pwm(1022, m) == 255);
  CHECK(scale_to_pwm(5000, m) == 255);
  CHECK(scale_to_pwm(-2147483647 - 1, m) == 255);
  int prev = 0;
  for (int c = 0; c <= 1023; ++c) {
    const int p = scale_to_pwm(c, m);
    CHECK(p >= prev);
    CHECK(p - prev <= 1);
    prev = p;
  }
  CHECK(clamp_command(2000, 1023) == 1023);
  CHECK(clamp_command(-2000, 1023) == -1023);
  CHECK(clamp_command(17, 1023) == 17);
}

TEST_CASE("motor: 8-bit input range (the book's motor sketch) maps 1:1") {
  MotorMapping m;
  m.command_max = 255;
  for (int c = 0; c <= 255; ++c) CHECK(scale_to_pwm(c, m) == c);
}
