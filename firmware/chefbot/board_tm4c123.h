// HAL of the TM4C123 LaunchPad under Energia (implements hal/hal.h).
#ifndef CHEFBOT_BOARD_TM4C123_H
#define CHEFBOT_BOARD_TM4C123_H

#include "src/core/config.h"
#include "src/hal/hal.h"

namespace chefbot {
namespace board {

// Pin set-up, I2C and the MPU6050 DMP; call once in setup() after Serial.begin().
void begin(const Config& cfg);
// The Hal wired to this board's drivers.
Hal hal();
// Call every loop() pass.
void feed_hardware_watchdog();
// 1 when the MPU6050 DMP initialised.
bool imu_ready();

}  // namespace board
}  // namespace chefbot

#endif
