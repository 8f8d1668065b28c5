#pragma once
#include <stdint.h>
#define HWREG(x) (*((volatile uint32_t*)(x)))
