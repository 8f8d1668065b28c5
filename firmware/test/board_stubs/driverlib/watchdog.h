#pragma once
#include <stdint.h>
#ifdef __cplusplus
extern "C" {
#endif
void WatchdogReloadSet(uint32_t base, uint32_t value);
void WatchdogResetEnable(uint32_t base);
void WatchdogEnable(uint32_t base);
void WatchdogIntClear(uint32_t base);
#ifdef __cplusplus
}
#endif
