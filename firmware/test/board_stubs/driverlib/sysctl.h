#pragma once
#include <stdint.h>
#define SYSCTL_PERIPH_WDOG0 0xf0000000
#ifdef __cplusplus
extern "C" {
#endif
void SysCtlPeripheralEnable(uint32_t periph);
uint32_t SysCtlClockGet(void);
void SysCtlReset(void);
#ifdef __cplusplus
}
#endif
