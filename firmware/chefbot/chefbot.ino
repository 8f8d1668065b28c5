// ChefBot LaunchPad firmware (Energia, TM4C123GXL). All behaviour is in the
// portable core (src/core, tested on the host); this sketch only wires the
// board's HAL to it. Protocol: PROTOCOL.md; wiring and flashing: README.md.
#include "board_tm4c123.h"
#include "src/core/firmware.h"

namespace {
// Defaults of src/core/config.h; change them there so host tests see them.
chefbot::Firmware firmware(chefbot::board::hal(), chefbot::Config());
}  // namespace

void setup() {
  Serial.begin(115200);
  chefbot::board::begin(firmware.config());
  firmware.begin();
}

void loop() {
  chefbot::board::feed_hardware_watchdog();
  firmware.poll();
}
