// Wiring of the ChefBot LaunchPad (TM4C123GXL), Energia pin names/numbers.
// Motor, encoder and HC-SR04 pins are the book's (chapter 8); the battery
// and reset pins are ours (the book never read the battery). Firmware
// behaviour (rates, timeouts, ranges, inversions) is in core/config.h.
#ifndef CHEFBOT_BOARD_CONFIG_H
#define CHEFBOT_BOARD_CONFIG_H

// VNH2SP30 dual driver (Pololu MD03A), through 3.3 V -> 5 V level shifters.
#define CHEFBOT_LEFT_INA 12    // PA_3
#define CHEFBOT_LEFT_INB 13    // PA_4
#define CHEFBOT_LEFT_PWM PC_6  // pin 35
#define CHEFBOT_RIGHT_INA 5    // PE_4
#define CHEFBOT_RIGHT_INB 6    // PE_5
#define CHEFBOT_RIGHT_PWM PC_5 // pin 36

// Quadrature encoders (Pololu 37D, 64 CPR at the motor shaft).
#define CHEFBOT_LEFT_ENC_A 31   // PF_4
#define CHEFBOT_LEFT_ENC_B 32   // PD_7 (NMI pin: locked at reset, see README)
#define CHEFBOT_RIGHT_ENC_A 33  // PD_6
#define CHEFBOT_RIGHT_ENC_B 34  // PC_7

// HC-SR04 (5 V part: echo through a divider or level shifter).
#define CHEFBOT_ULTRASONIC_ECHO 9   // PA_6
#define CHEFBOT_ULTRASONIC_TRIG 10  // PA_7

// MPU6050 on I2C module 3: PD_0 = SCL, PD_1 = SDA (pins 23, 24). On the
// LaunchPad PD_0/PD_1 are tied to PB_6/PB_7 through R9/R10; leave PB_6/PB_7
// unused or remove the resistors.
#define CHEFBOT_I2C_MODULE 3

// Battery divider output (47k over 10k, see core/config.h): PE_3 = A0.
#define CHEFBOT_BATTERY_ADC PE_3

// Reset. 0: software reset (SysCtlReset), needs no wiring. Otherwise the pin
// wired to RST, as in the book (pulled low to reset).
#define CHEFBOT_RESET_PIN 0

// Hardware watchdog: resets the MCU when loop() stops running for this long
// (a hung I2C transfer, a bug), which also stops the motors. 0 disables it.
#define CHEFBOT_HW_WATCHDOG_MS 250

#endif
