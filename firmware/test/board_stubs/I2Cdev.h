// Compile-only stand-in for i2cdevlib's I2Cdev (see Energia.h).
#pragma once
#include <stdint.h>
