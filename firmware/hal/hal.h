// Hardware interfaces the firmware core talks to. The LaunchPad board file
// (chefbot/board_tm4c123.cpp) implements them with Energia calls; the host
// library (host/) implements them in memory for tests and the simulator.
//
// No virtual destructors on purpose: the objects are never deleted through
// these interfaces, and a virtual destructor would drag operator delete (and
// with it the heap) into the board image.
#ifndef CHEFBOT_HAL_HAL_H
#define CHEFBOT_HAL_HAL_H

#include <stddef.h>
#include <stdint.h>

namespace chefbot {

struct MotorOutput;
struct Quaternion;

enum Side : uint8_t { kLeft = 0, kRight = 1 };

// Free-running microsecond clock (Energia micros(); wraps every 71.6 min).
class Clock {
 public:
  virtual uint32_t micros() = 0;

 protected:
  ~Clock() {}
};

// The UART to the PC. Both calls must return immediately.
class SerialPort {
 public:
  // Next received byte, or -1 when none is waiting.
  virtual int read_byte() = 0;
  // Bytes that can be written now without blocking.
  virtual size_t tx_space() = 0;
  virtual void write(const char* data, size_t len) = 0;

 protected:
  ~SerialPort() {}
};

// INA/INB/PWM of the VNH2SP30 for one motor.
class MotorPins {
 public:
  virtual void apply(Side side, const MotorOutput& out) = 0;

 protected:
  ~MotorPins() {}
};

// Receives encoder edges. The core implements it; the board's pin-change
// interrupts call it with both channel levels read after the edge.
class EncoderSink {
 public:
  // Current levels at start-up: sets the reference state without counting.
  virtual void encoder_prime(Side side, bool a, bool b) = 0;
  virtual void encoder_edge(Side side, bool a, bool b) = 0;

 protected:
  ~EncoderSink() {}
};

class EncoderPins {
 public:
  // Sets up the pins, reports the current levels through `sink` (to prime the
  // decoders) and enables the interrupts that feed it afterwards.
  virtual void begin(EncoderSink& sink) = 0;

 protected:
  ~EncoderPins() {}
};

// Receives HC-SR04 echo edges (level after the edge, timestamp in us).
class EchoSink {
 public:
  virtual void echo_edge(bool level, uint32_t t_us) = 0;

 protected:
  ~EchoSink() {}
};

class UltrasonicPins {
 public:
  virtual void begin(EchoSink& sink) = 0;
  // One 10 us trigger pulse; the only busy wait in the firmware.
  virtual void trigger() = 0;

 protected:
  ~UltrasonicPins() {}
};

// Orientation from the IMU (MPU6050 DMP on the robot).
class ImuSource {
 public:
  // Fills q and returns true when a new sample is ready; never waits.
  virtual bool poll(Quaternion& q) = 0;

 protected:
  ~ImuSource() {}
};

// Battery voltage ADC channel.
class AnalogInput {
 public:
  virtual uint16_t read_raw() = 0;

 protected:
  ~AnalogInput() {}
};

// Output wired to the board's reset pin (the book's "r" command).
class ResetLine {
 public:
  virtual void reset_board() = 0;

 protected:
  ~ResetLine() {}
};

struct Hal {
  Clock* clock;
  SerialPort* serial;
  MotorPins* motors;
  EncoderPins* encoders;     // may be null (host: edges are injected)
  UltrasonicPins* ultrasonic;
  ImuSource* imu;            // may be null (no IMU fitted)
  AnalogInput* battery;      // may be null (book: not wired)
  ResetLine* reset;
};

}  // namespace chefbot

#endif
