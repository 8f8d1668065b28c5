// Compile-only stand-in for the i2cdevlib MPU6050 DMP API used by the board
// HAL (see Energia.h); signatures as in i2cdevlib's MPU6050 library.
#pragma once
#include <stdint.h>
class Quaternion {
 public:
  float w, x, y, z;
};
class MPU6050 {
 public:
  void initialize();
  bool testConnection();
  uint8_t dmpInitialize();
  void setDMPEnabled(bool enabled);
  uint16_t dmpGetFIFOPacketSize();
  uint16_t getFIFOCount();
  void resetFIFO();
  void getFIFOBytes(uint8_t* data, uint8_t length);
  uint8_t dmpGetQuaternion(Quaternion* q, const uint8_t* packet = 0);
};
