// Energia implementation of the HAL for the ChefBot LaunchPad. Everything
// here is a thin pin/peripheral wrapper; behaviour lives in src/core.
#include <Energia.h>
#include <Wire.h>

// i2cdevlib (Jeff Rowberg), installed as Energia libraries "I2Cdev" and
// "MPU6050". MotionApps20 defines its DMP image in the header: include it
// in this one translation unit only.
#include "I2Cdev.h"
#include "MPU6050_6Axis_MotionApps20.h"

#include "inc/hw_gpio.h"
#include "inc/hw_memmap.h"
#include "inc/hw_types.h"
#include "driverlib/sysctl.h"
#include "driverlib/watchdog.h"

#include "board_config.h"
#include "board_tm4c123.h"
#include "src/core/line_format.h"
#include "src/core/motor.h"
#include "src/core/scheduler.h"

namespace chefbot {
namespace board {

namespace {

struct MotorPinMap {
  uint8_t ina;
  uint8_t inb;
  uint8_t pwm;
};
const MotorPinMap kMotors[2] = {
    {CHEFBOT_LEFT_INA, CHEFBOT_LEFT_INB, CHEFBOT_LEFT_PWM},
    {CHEFBOT_RIGHT_INA, CHEFBOT_RIGHT_INB, CHEFBOT_RIGHT_PWM},
};
const uint8_t kEncA[2] = {CHEFBOT_LEFT_ENC_A, CHEFBOT_RIGHT_ENC_A};
const uint8_t kEncB[2] = {CHEFBOT_LEFT_ENC_B, CHEFBOT_RIGHT_ENC_B};

EncoderSink* g_encoder_sink = 0;
EchoSink* g_echo_sink = 0;
bool g_imu_ready = false;

// ISRs: read both channels after the edge; the decoder works out the rest.
void left_encoder_isr() {
  g_encoder_sink->encoder_edge(kLeft, digitalRead(kEncA[0]) == HIGH, digitalRead(kEncB[0]) == HIGH);
}
void right_encoder_isr() {
  g_encoder_sink->encoder_edge(kRight, digitalRead(kEncA[1]) == HIGH, digitalRead(kEncB[1]) == HIGH);
}
void echo_isr() { g_echo_sink->echo_edge(digitalRead(CHEFBOT_ULTRASONIC_ECHO) == HIGH, micros()); }

class Clock123 : public Clock {
 public:
  uint32_t micros() override { return ::micros(); }
};

class Serial123 : public SerialPort {
 public:
  void configure(const Config& cfg) { pacer_.configure(cfg.tx_buffer_bytes, cfg.tx_bytes_per_s); }
  int read_byte() override { return Serial.available() > 0 ? Serial.read() : -1; }
  // Energia's Serial.write() blocks while its ring buffer is full; the pacer
  // tracks the fill level so the core never writes more than fits.
  size_t tx_space() override { return pacer_.space(::micros()); }
  void write(const char* data, size_t len) override {
    Serial.write(reinterpret_cast<const uint8_t*>(data), len);
    pacer_.wrote(static_cast<uint32_t>(len), ::micros());
  }

 private:
  TxPacer pacer_;
};

class Motors123 : public MotorPins {
 public:
  void apply(Side side, const MotorOutput& out) override {
    const MotorPinMap& p = kMotors[side & 1];
    // Lower the input that goes low first: going CW -> CCW by raising INB
    // first would pass through INA=INB=1 (brake to Vcc) for a moment.
    if (!out.ina) digitalWrite(p.ina, LOW);
    if (!out.inb) digitalWrite(p.inb, LOW);
    if (out.ina) digitalWrite(p.ina, HIGH);
    if (out.inb) digitalWrite(p.inb, HIGH);
    analogWrite(p.pwm, out.pwm);
  }
};

class Encoders123 : public EncoderPins {
 public:
  void configure(const Config& cfg) { a_only_ = cfg.encoder_mode != EncoderMode::X4; }
  void begin(EncoderSink& sink) override {
    g_encoder_sink = &sink;
    // PD7 is the NMI pin: locked against reconfiguration at reset.
    HWREG(GPIO_PORTD_BASE + GPIO_O_LOCK) = GPIO_LOCK_KEY;
    HWREG(GPIO_PORTD_BASE + GPIO_O_CR) |= 0x80;
    HWREG(GPIO_PORTD_BASE + GPIO_O_LOCK) = 0;
    for (int s = 0; s < 2; ++s) {
      pinMode(kEncA[s], INPUT_PULLUP);
      pinMode(kEncB[s], INPUT_PULLUP);
      sink.encoder_prime(static_cast<Side>(s), digitalRead(kEncA[s]) == HIGH, digitalRead(kEncB[s]) == HIGH);
    }
    attachInterrupt(kEncA[0], left_encoder_isr, CHANGE);
    attachInterrupt(kEncA[1], right_encoder_isr, CHANGE);
    if (!a_only_) {
      attachInterrupt(kEncB[0], left_encoder_isr, CHANGE);
      attachInterrupt(kEncB[1], right_encoder_isr, CHANGE);
    }
  }

 private:
  bool a_only_ = false;
};

class Ultrasonic123 : public UltrasonicPins {
 public:
  void begin(EchoSink& sink) override {
    g_echo_sink = &sink;
    pinMode(CHEFBOT_ULTRASONIC_TRIG, OUTPUT);
    digitalWrite(CHEFBOT_ULTRASONIC_TRIG, LOW);
    pinMode(CHEFBOT_ULTRASONIC_ECHO, INPUT);
    attachInterrupt(CHEFBOT_ULTRASONIC_ECHO, echo_isr, CHANGE);
  }
  void trigger() override {
    digitalWrite(CHEFBOT_ULTRASONIC_TRIG, HIGH);
    delayMicroseconds(10);
    digitalWrite(CHEFBOT_ULTRASONIC_TRIG, LOW);
  }
};

class Imu123 : public ImuSource {
 public:
  void begin() {
    Wire.setModule(CHEFBOT_I2C_MODULE);
    Wire.begin();
    mpu_.initialize();
    if (!mpu_.testConnection()) return;
    if (mpu_.dmpInitialize() != 0) return;
    mpu_.setDMPEnabled(true);
    packet_size_ = mpu_.dmpGetFIFOPacketSize();
    g_imu_ready = packet_size_ > 0 && packet_size_ <= sizeof(fifo_);
  }
  // Polled, never waits for data: reads only whole packets already in the
  // FIFO and keeps the newest.
  bool poll(Quaternion& q) override {
    if (!g_imu_ready) return false;
    uint16_t count = mpu_.getFIFOCount();
    if (count >= 1024) {  // overflowed: contents are misaligned
      mpu_.resetFIFO();
      return false;
    }
    if (count < packet_size_) return false;
    while (count >= packet_size_) {
      mpu_.getFIFOBytes(fifo_, static_cast<uint8_t>(packet_size_));
      count = static_cast<uint16_t>(count - packet_size_);
    }
    ::Quaternion dq;
    mpu_.dmpGetQuaternion(&dq, fifo_);
    q.x = dq.x;
    q.y = dq.y;
    q.z = dq.z;
    q.w = dq.w;
    return true;
  }

 private:
  MPU6050 mpu_;
  uint16_t packet_size_ = 0;
  uint8_t fifo_[64];
};

// Energia's analogRead() on the TM4C123 returns the raw 12-bit count.
class Battery123 : public AnalogInput {
 public:
  uint16_t read_raw() override { return static_cast<uint16_t>(analogRead(CHEFBOT_BATTERY_ADC)); }
};

class Reset123 : public ResetLine {
 public:
  void reset_board() override {
    Serial.flush();
#if CHEFBOT_RESET_PIN
    pinMode(CHEFBOT_RESET_PIN, OUTPUT);
    digitalWrite(CHEFBOT_RESET_PIN, LOW);
    delay(100);
#endif
    SysCtlReset();
  }
};

Clock123 g_clock;
Serial123 g_serial;
Motors123 g_motors;
Encoders123 g_encoders;
Ultrasonic123 g_ultrasonic;
Imu123 g_imu;
Battery123 g_battery;
Reset123 g_reset;

}  // namespace

void begin(const Config& cfg) {
  g_serial.configure(cfg);
  g_encoders.configure(cfg);
  for (int s = 0; s < 2; ++s) {
    pinMode(kMotors[s].ina, OUTPUT);
    pinMode(kMotors[s].inb, OUTPUT);
    pinMode(kMotors[s].pwm, OUTPUT);
  }
  // The DMP upload takes a while; the motors are braked by the core's
  // begin() only after this, but the driver inputs are low (coast) meanwhile.
  g_imu.begin();
#if CHEFBOT_HW_WATCHDOG_MS
  SysCtlPeripheralEnable(SYSCTL_PERIPH_WDOG0);
  // The watchdog resets on its second time-out: load half the period.
  WatchdogReloadSet(WATCHDOG0_BASE, SysCtlClockGet() / 1000u * (CHEFBOT_HW_WATCHDOG_MS / 2));
  WatchdogResetEnable(WATCHDOG0_BASE);
  WatchdogEnable(WATCHDOG0_BASE);
#endif
}

Hal hal() {
  Hal h;
  h.clock = &g_clock;
  h.serial = &g_serial;
  h.motors = &g_motors;
  h.encoders = &g_encoders;
  h.ultrasonic = &g_ultrasonic;
  h.imu = &g_imu;
  h.battery = &g_battery;
  h.reset = &g_reset;
  return h;
}

void feed_hardware_watchdog() {
#if CHEFBOT_HW_WATCHDOG_MS
  WatchdogIntClear(WATCHDOG0_BASE);
#endif
}

bool imu_ready() { return g_imu_ready; }

}  // namespace board
}  // namespace chefbot
