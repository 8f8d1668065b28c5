// libFuzzer target: the whole core on the in-memory board, driven by an
// operation stream decoded from the input: received bytes (random and valid
// commands), clock steps and jumps (including across the 2^32 us wrap),
// encoder edges, echo widths, IMU samples (incl. NaN/inf) and ADC values.
// After every operation the board-level invariants are checked:
//   * the driver never sees INA=INB=1; PWM <= pwm_max; stopped = braked;
//   * no command for longer than the timeout => motors stopped;
//   * every line on the wire is complete, known, within length, CRC-correct;
//   * ultrasonic triggers are >= 60 ms apart.
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cstdio>
#include <cstdlib>
#include <string>

#include "../core/crc8.h"
#include "../host/host_board.h"

using namespace chefbot;
using chefbot::host::HostBoard;

namespace {

struct Reader {
  const uint8_t* p;
  size_t n;
  uint8_t u8() {
    if (!n) return 0;
    --n;
    return *p++;
  }
  uint16_t u16() { return static_cast<uint16_t>(u8() | (u8() << 8)); }
  uint32_t u32() { return static_cast<uint32_t>(u16()) | (static_cast<uint32_t>(u16()) << 16); }
  float f32() {
    const uint32_t bits = u32();
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
  }
};

void check_motors(HostBoard& b) {
  const Config& c = b.firmware().config();
  const bool run = b.firmware().drive_state() == DriveState::Run;
  for (int s = 0; s < 2; ++s) {
    const MotorOutput m = b.motor(static_cast<Side>(s));
    if (m.ina && m.inb) abort();
    if (!run && (m.ina || m.inb || m.pwm != c.brake_pwm)) abort();
    if (run && (m.ina || m.inb) && m.pwm > c.pwm_max) abort();
  }
}

// A reset loses the bytes still in the UART, so the line in flight may be
// cut; the hello line's leading '\n' ends it. One such line per reset is
// allowed; blank lines are allowed (that same '\n').
bool line_ok(const std::string& line, bool crc) {
  if (line == "\n") return true;
  if (line.size() > LineBuilder::kCapacity || line.size() < 3) return false;
  if (!strchr("vteusibd", line[0]) || line[1] != '\t') return false;
  for (size_t i = 0; i + 1 < line.size(); ++i) {
    const unsigned char c = static_cast<unsigned char>(line[i]);
    if ((c < 0x20 && c != '\t') || c > 0x7E) return false;
  }
  if (crc) {
    const size_t k = line.size();
    if (k < 6 || line[k - 5] != '\t' || line[k - 4] != '*') return false;
    char want[3];
    snprintf(want, sizeof want, "%02X", crc8(line.data(), k - 5));
    if (line.compare(k - 3, 2, want) != 0) return false;
  }
  return true;
}

void check_wire(HostBoard& b, std::string& pending, bool crc, uint32_t& cut_allowance) {
  uint8_t buf[4096];
  size_t n;
  while ((n = b.read_tx(buf, sizeof buf)) > 0) pending.append(reinterpret_cast<char*>(buf), n);
  size_t nl;
  while ((nl = pending.find('\n')) != std::string::npos) {
    const std::string line = pending.substr(0, nl + 1);
    pending.erase(0, nl + 1);
    if (!line_ok(line, crc)) {
      if (cut_allowance == 0) abort();
      --cut_allowance;
    }
  }
  // Lines are written whole, so a partial line can only be one in flight.
  if (pending.size() > LineBuilder::kCapacity) abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Reader r{data, size};
  Config cfg;
  const uint8_t f = r.u8();
  cfg.status_rate_hz = 1u + r.u8() % 100u;
  cfg.watchdog_ms = 20u + r.u16() % 2000u;
  cfg.command_max = (f & 1) ? 1023 : 1 + r.u16() % 9999;
  cfg.encoder_mode = (f & 2) ? EncoderMode::X4 : ((f & 4) ? EncoderMode::X2 : EncoderMode::X1);
  cfg.tx_checksum = (f & 8) == 0;
  cfg.invert_left = (f & 16) != 0;
  cfg.diag_every_cycles = r.u8() % 8u;
  cfg.brake_pwm = (f & 32) ? 255 : r.u8();
  HostBoard b(cfg);
  b.set_loop_us(50u + r.u8() * 8u);
  if (f & 64) b.set_instant_tx(true);
  const uint32_t timeout_us = b.firmware().config().watchdog_ms * 1000u;

  std::string pending;
  uint32_t resets = 0;
  uint32_t cut_allowance = 0;
  bool spacing_known = true;
  uint64_t since_rx = 0;  // simulated time with no byte sent to the board
  uint32_t triggers = b.triggers();
  uint32_t last_trigger = b.last_trigger_us();
  int ops = 0;
  while (r.n > 0 && ops++ < 400) {
    // The core takes at most 64 bytes per pass, so a backlog may still be
    // parsed during this op: count time without input from when it is gone.
    const bool backlog = b.rx_pending() > 0;
    switch (r.u8() % 11) {
      case 0: {  // raw bytes
        uint8_t buf[64];
        const size_t k = r.u8() % sizeof buf;
        for (size_t i = 0; i < k; ++i) buf[i] = r.u8();
        b.feed(buf, k);
        if (k) since_rx = 0;
        break;
      }
      case 1: {  // small clock step
        const uint32_t us = r.u16();
        b.advance(us);
        since_rx += us;
        break;
      }
      case 2: {  // clock jump (stall), then a little running
        b.set_clock(b.now() + r.u32());
        spacing_known = false;  // modular time cannot order triggers across a jump
        b.advance(1000);
        since_rx += 1000;
        break;
      }
      case 3:
        b.encoder_edge(static_cast<Side>(r.u8() & 1), r.u8() & 1, r.u8() & 1);
        break;
      case 4:
        b.encoder_step(static_cast<Side>(r.u8() & 1), static_cast<int8_t>(r.u8()));
        break;
      case 5:
        b.set_echo_us(static_cast<int32_t>(r.u16()) - 1000);
        break;
      case 6: {
        Quaternion q;
        q.x = r.f32();
        q.y = r.f32();
        q.z = r.f32();
        q.w = r.f32();
        b.set_imu(q);
        break;
      }
      case 7:
        b.set_battery_raw(r.u16());
        break;
      case 8: {  // a well-formed command, sometimes with checksum
        char line[48];
        const int a = static_cast<int16_t>(r.u16()) % 12000;
        const int c = static_cast<int16_t>(r.u16()) % 12000;
        int n = snprintf(line, sizeof line, "s %d %d", a, c);
        if (r.u8() & 1) n += snprintf(line + n, sizeof line - static_cast<size_t>(n), " *%02X", crc8(line, static_cast<size_t>(n)));
        line[n++] = (r.u8() & 1) ? '\r' : '\n';
        b.feed(reinterpret_cast<const uint8_t*>(line), static_cast<size_t>(n));
        since_rx = 0;
        break;
      }
      case 9:
        b.feed(reinterpret_cast<const uint8_t*>("r\r"), 2);
        since_rx = 0;
        break;
      case 10:
        b.clear_imu();
        break;
    }
    if (backlog) since_rx = 0;
    check_motors(b);
    if (b.resets() != resets) {
      cut_allowance += b.resets() - resets;
      resets = b.resets();
    }
    check_wire(b, pending, cfg.tx_checksum, cut_allowance);
    // The last byte is parsed at the latest in the first pass after it was
    // sent (or, with a backlog, during the op that drained it).
    if (since_rx > timeout_us + 2u * 2098u && b.firmware().drive_state() == DriveState::Run) abort();
    // A reset restarts ranging at once (on the robot, booting takes longer
    // than 60 ms anyway), so spacing is only checked between triggers of the
    // same power-on.
    if (b.triggers() != triggers) {
      if (spacing_known && b.triggers_since_power_on() >= 2 && b.last_trigger_us() - last_trigger < 60000u) abort();
      spacing_known = true;
      triggers = b.triggers();
      last_trigger = b.last_trigger_us();
    }
  }
  return 0;
}
