// Compile-only stand-in (see Energia.h).
#pragma once
#include <stdint.h>
class TwoWire {
 public:
  void setModule(unsigned long module);
  void begin();
};
extern TwoWire Wire;
