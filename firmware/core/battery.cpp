#include "battery.h"

namespace chefbot {

uint32_t battery_millivolts(uint32_t raw, const BatteryDivider& d) {
  if (d.adc_max_raw == 0 || d.r_bottom_ohm == 0) return 0;
  if (raw > d.adc_max_raw) raw = d.adc_max_raw;
  // Scale the divider ratio to 1/1024 steps first so the products stay in
  // 32 bits for a 12-bit ADC, 3.3 V reference and divider ratios up to ~80.
  const uint32_t ratio_q10 = ((d.r_top_ohm + d.r_bottom_ohm) * 1024u + d.r_bottom_ohm / 2u) / d.r_bottom_ohm;
  const uint32_t adc_mv_x16 = (raw * d.adc_ref_mv * 16u + d.adc_max_raw / 2u) / d.adc_max_raw;
  return (adc_mv_x16 * ratio_q10 + (1u << 13)) >> 14;
}

void BatteryMonitor::sample(uint32_t raw) {
  const uint32_t mv = battery_millivolts(raw, div_);
  if (!have_) {
    filtered_mv_ = mv;
    have_ = true;
    return;
  }
  // Signed step so the average moves both ways; |step| < 2^31 always.
  const int32_t step = (static_cast<int32_t>(mv) - static_cast<int32_t>(filtered_mv_)) / 8;
  filtered_mv_ = static_cast<uint32_t>(static_cast<int32_t>(filtered_mv_) + step);
}

}  // namespace chefbot
