// Battery voltage from the ADC through a resistor divider (see Config):
//   V_bat = raw / adc_max * V_ref * (R_top + R_bottom) / R_bottom
// smoothed by a 1/8 exponential average, because motor current makes the
// raw reading jump by tenths of a volt.
#ifndef CHEFBOT_CORE_BATTERY_H
#define CHEFBOT_CORE_BATTERY_H

#include <stdint.h>

namespace chefbot {

struct BatteryDivider {
  uint32_t r_top_ohm = 47000;
  uint32_t r_bottom_ohm = 10000;
  uint32_t adc_ref_mv = 3300;
  uint32_t adc_max_raw = 4095;
};

// Unfiltered conversion, millivolts at the battery.
uint32_t battery_millivolts(uint32_t raw, const BatteryDivider& d);

class BatteryMonitor {
 public:
  explicit BatteryMonitor(const BatteryDivider& d = BatteryDivider()) : div_(d) {}
  void configure(const BatteryDivider& d) { div_ = d; }
  void reset() { have_ = false; filtered_mv_ = 0; }
  void sample(uint32_t raw);
  uint32_t millivolts() const { return filtered_mv_; }
  bool valid() const { return have_; }

 private:
  BatteryDivider div_;
  uint32_t filtered_mv_ = 0;
  bool have_ = false;
};

}  // namespace chefbot

#endif
