/* C API of the host build of the ChefBot firmware (build/libchefbot_fw.so).
 * Loaded with ctypes by chefbot_firmware.host.FirmwareHost; see PROTOCOL.md,
 * "Host library". All functions take the handle from cfw_create(); none of
 * them blocks; time only moves in cfw_advance(). */
#ifndef CHEFBOT_FW_H
#define CHEFBOT_FW_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif
/* The library is built with hidden visibility; only this API is exported. */
#if defined(__GNUC__)
#pragma GCC visibility push(default)
#endif

#define CFW_API_VERSION 1

typedef struct cfw_board cfw_board;

int cfw_api_version(void);

cfw_board* cfw_create(void);
void cfw_destroy(cfw_board* b);
/* Sets a Config field by name (see core/config.h) or the host-only keys
 * "loop_us" (main-loop period, default 200) and "instant_tx" (0/1).
 * Config fields take effect at the next cfw_power_on(). 0 = ok, -1 = unknown. */
int cfw_configure(cfw_board* b, const char* key, int64_t value);
void cfw_power_on(cfw_board* b);

size_t cfw_feed(cfw_board* b, const uint8_t* data, size_t len);
void cfw_advance(cfw_board* b, uint64_t us);
void cfw_poll(cfw_board* b);
uint32_t cfw_now_us(cfw_board* b);
void cfw_set_clock_us(cfw_board* b, uint32_t us);

size_t cfw_tx_available(cfw_board* b);
size_t cfw_read_tx(cfw_board* b, uint8_t* out, size_t max);

void cfw_get_motor(cfw_board* b, int side, int* ina, int* inb, int* pwm);
double cfw_wheel_duty(cfw_board* b, int side);
int32_t cfw_command(cfw_board* b, int side);
int cfw_drive_state(cfw_board* b); /* 0 idle, 1 run, 2 watchdog timeout */

void cfw_encoder_edge(cfw_board* b, int side, int a, int b_level);
void cfw_encoder_step(cfw_board* b, int side, int32_t steps);
void cfw_wheel_advance(cfw_board* b, int side, int32_t edges);
void cfw_set_encoder_count(cfw_board* b, int side, int32_t count);
int32_t cfw_encoder_count(cfw_board* b, int side);

void cfw_set_ultrasonic_echo_us(cfw_board* b, int32_t us); /* <= 0: no echo */
void cfw_set_imu_quaternion(cfw_board* b, double x, double y, double z, double w);
void cfw_clear_imu(cfw_board* b);
void cfw_set_battery_raw(cfw_board* b, uint16_t raw);
void cfw_set_battery_volts(cfw_board* b, double volts);

/* Counter by name; returns 0 and sets *found = 0 for an unknown name. */
uint64_t cfw_stat(cfw_board* b, const char* name, int* found);

#if defined(__GNUC__)
#pragma GCC visibility pop
#endif
#ifdef __cplusplus
}
#endif

#endif
