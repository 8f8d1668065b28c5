// Compile-only stand-in for the Energia core API used by the board HAL
// (`make board-check`): declarations only, so typos and type errors in
// chefbot/ are caught without installing Energia. Not linked, never run.
#pragma once
#include <stddef.h>
#include <stdint.h>
#define HIGH 1
#define LOW 0
#define INPUT 0
#define OUTPUT 1
#define INPUT_PULLUP 2
#define CHANGE 4
#define RISING 3
#define PC_5 36
#define PC_6 35
#define PE_3 29
void pinMode(uint8_t pin, uint8_t mode);
void digitalWrite(uint8_t pin, uint8_t value);
uint8_t digitalRead(uint8_t pin);
void analogWrite(uint8_t pin, int value);
uint16_t analogRead(uint8_t pin);
void attachInterrupt(uint8_t pin, void (*isr)(void), int mode);
unsigned long micros(void);
void delay(uint32_t ms);
void delayMicroseconds(unsigned int us);
class HardwareSerial {
 public:
  void begin(unsigned long baud);
  int available();
  int read();
  size_t write(const uint8_t* buf, size_t len);
  void flush();
};
extern HardwareSerial Serial;
