// The whole core on the in-memory board: what the PC sees on the wire.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdlib>
#include <string>

#include "../../host/host_board.h"
#include "helpers.h"

using namespace chefbot;
using chefbot::host::HostBoard;
using testing::fields;
using testing::lines_of;
using testing::lines_with_tag;

namespace {

void send(HostBoard& b, const std::string& s) {
  b.feed(reinterpret_cast<const uint8_t*>(s.data()), s.size());
}

std::string last_line(HostBoard& b, char tag, std::string& acc) {
  acc += b.read_tx_string();
  const auto ls = lines_with_tag(acc, tag);
  return ls.empty() ? std::string() : ls.back();
}

}  // namespace

TEST_CASE("firmware: hello line on power-up, motors braked, idle") {
  HostBoard b;
  b.advance(20000);
  const std::string out = b.read_tx_string();
  const auto lines = lines_of(out);
  REQUIRE(lines.size() > 2);
  CHECK(lines[0] == "\n");  // ends a line cut by the reset on the PC side
  CHECK(fields(lines[1]) == std::vector<std::string>{"v", "1", "chefbot_fw-1.0.0", "30", "500", "4", "1023"});
  CHECK(testing::checksum_ok(lines[1]));
  for (int s = 0; s < 2; ++s) {
    CHECK_FALSE(b.motor(static_cast<Side>(s)).ina);
    CHECK_FALSE(b.motor(static_cast<Side>(s)).inb);
    CHECK(b.motor(static_cast<Side>(s)).pwm == 255);
  }
  CHECK(fields(lines_with_tag(out, 's').at(0)) == std::vector<std::string>{"s", "0.00", "0.00", "idle"});
}

TEST_CASE("firmware: s 100 -100 drives both wheels per the truth table; the echo reports it") {
  HostBoard b;
  send(b, "s 100 -100\r");
  b.advance(1000);
  // Left: positive = clockwise. Right is mounted mirrored: negative command
  // becomes clockwise at its pins.
  CHECK(b.motor(kLeft).ina);
  CHECK_FALSE(b.motor(kLeft).inb);
  CHECK(b.motor(kLeft).pwm == 25);  // 100/1023*255 = 24.9
  CHECK(b.motor(kRight).ina);
  CHECK_FALSE(b.motor(kRight).inb);
  CHECK(b.motor(kRight).pwm == 25);
  CHECK(b.wheel_duty(kLeft) == doctest::Approx(25.0 / 255));
  CHECK(b.wheel_duty(kRight) == doctest::Approx(-25.0 / 255));
  b.advance(100000);
  std::string acc;
  CHECK(fields(last_line(b, 's', acc)) == std::vector<std::string>{"s", "100.00", "-100.00", "run"});
}

TEST_CASE("firmware: watchdog stops at the timeout, never before, resumes on a new command") {
  HostBoard b;
  b.set_loop_us(100);
  b.advance(5000);
  send(b, "s 500 500\r");
  b.advance(100);  // command parsed in this pass
  const uint32_t t_cmd = b.now();
  CHECK(b.firmware().drive_state() == DriveState::Run);
  b.advance(500000 - 200);
  CHECK(b.now() - t_cmd < 500000);
  CHECK(b.motor(kLeft).ina);
  CHECK(b.motor(kLeft).pwm == 125);
  b.advance(300);
  CHECK(b.firmware().drive_state() == DriveState::Timeout);
  CHECK_FALSE(b.motor(kLeft).ina);
  CHECK_FALSE(b.motor(kLeft).inb);
  CHECK(b.motor(kLeft).pwm == 255);
  // Reported in the next status line.
  b.read_tx_string();
  b.advance(40000);
  std::string acc;
  CHECK(fields(last_line(b, 's', acc)) == std::vector<std::string>{"s", "0.00", "0.00", "timeout"});
  // Stays stopped without a command, also when garbage or errors arrive.
  send(b, "s 2000 0\rs nan 1\rhello\r\r");
  b.advance(2000000);
  CHECK(b.firmware().drive_state() == DriveState::Timeout);
  CHECK(b.motor(kLeft).pwm == 255);
  CHECK_FALSE(b.motor(kLeft).ina);
  send(b, "s -300 0\r");
  b.advance(200);
  CHECK(b.firmware().drive_state() == DriveState::Run);
  CHECK(b.motor(kLeft).inb);
  CHECK(b.motor(kLeft).pwm == 75);
  CHECK(b.motor(kRight).pwm == 255);  // zero command = brake
  CHECK(b.firmware().diag(b.now()).watchdog_trips == 1);
}

TEST_CASE("firmware: commands every 100 ms keep the motors running for minutes") {
  HostBoard b;
  b.set_clock(0xFFFFFFFFu - 30000000u);  // crosses the micros() wrap
  for (int i = 0; i < 1200; ++i) {
    send(b, "s 1023 -1023\r");
    b.advance(100000);
    REQUIRE(b.firmware().drive_state() == DriveState::Run);
    REQUIRE(b.motor(kLeft).pwm == 255);
  }
  CHECK(b.firmware().diag(b.now()).watchdog_trips == 0);
}

TEST_CASE("firmware: status rate, order and checksums over 10 s") {
  HostBoard b;
  b.set_echo_us(580);
  Quaternion q;
  b.set_imu(q);
  b.advance(10000000);
  const std::string out = b.read_tx_string();
  const auto ts = lines_with_tag(out, 't');
  CHECK(ts.size() >= 300);
  CHECK(ts.size() <= 301);
  const auto lines = lines_of(out);
  for (size_t i = 1; i < lines.size(); ++i) CHECK_MESSAGE(testing::checksum_ok(lines[i]), lines[i]);
  // One cycle in the book's order, after "\n" and the hello line.
  std::string order;
  for (size_t i = 2; i < 8; ++i) order += lines[i][0];
  CHECK(order == "teusib");
  // The interval reported in `t` is the status period.
  const auto f = fields(ts[100]);
  CHECK(f[2] == "0.033");
  CHECK(lines_with_tag(out, 'd').size() == 10);
}

TEST_CASE("firmware: serial budget at the default rate, measured on the wire") {
  HostBoard b;
  // Worst-case field widths everywhere.
  b.set_encoder_count(kLeft, -2147483647 - 1);
  b.set_encoder_count(kRight, -2147483647 - 1);
  b.set_echo_us(400 * 58);
  Quaternion q;
  q.x = -0.5f;
  q.y = -0.5f;
  q.z = -0.5f;
  q.w = -0.5f;
  b.set_imu(q);
  b.set_battery_volts(18.8);
  send(b, "s -1023 -1023\r");
  b.advance(1000000);
  b.read_tx_string();
  const uint64_t before = b.tx_bytes_total();
  for (int i = 0; i < 100; ++i) {
    send(b, "s -1023 -1023\r");
    b.advance(100000);
  }
  const double bytes_per_s = static_cast<double>(b.tx_bytes_total() - before) / 10.0;
  MESSAGE("measured board->PC load at 30 Hz: " << bytes_per_s << " B/s = " << bytes_per_s / 115.2 << " % of 11520 B/s");
  CHECK(bytes_per_s <= 0.5 * 11520);
  CHECK(bytes_per_s >= 30 * 130);
  CHECK(b.firmware().tx_dropped_lines() == 0);
  // The static bound used in PROTOCOL.md.
  CHECK(30 * kMaxStatusCycleBytes + kMaxLenDiag <= 11520 / 2);
}

TEST_CASE("firmware: an over-budget rate drops whole lines, never blocks or cuts them") {
  HostBoard b(([] {
    Config c;
    c.status_rate_hz = 200;
    return c;
  })());
  Quaternion q;
  b.set_imu(q);
  for (int i = 0; i < 50; ++i) {
    send(b, "s 10 10\r");
    b.advance(100000);
    REQUIRE(b.firmware().drive_state() == DriveState::Run);
  }
  CHECK(b.firmware().tx_dropped_lines() > 0);
  const std::string out = b.read_tx_string();
  const auto lines = lines_of(out);
  for (size_t i = 1; i < lines.size(); ++i) CHECK(testing::checksum_ok(lines[i]));
}

TEST_CASE("firmware: commands split across reads and polls, \\r\\n, flood of garbage") {
  HostBoard b;
  const std::string cmd = "s 200 -200\r\n";
  for (char c : cmd) {
    send(b, std::string(1, c));
    b.advance(300);
  }
  CHECK(b.firmware().command(kLeft) == 200);
  CHECK(b.firmware().rx_stats().empty == 0);
  // 64 KiB of random bytes with no '\r'/'\n', then a command.
  std::string junk;
  uint32_t seed = 7;
  for (int i = 0; i < 4000; ++i) {
    seed = seed * 1664525u + 1013904223u;
    char c = static_cast<char>(seed >> 24);
    if (c == '\r' || c == '\n') c = 'x';
    junk += c;
  }
  send(b, junk);
  send(b, "\rs 1 2\r");
  b.advance(200000);
  CHECK(b.firmware().command(kLeft) == 1);
  CHECK(b.firmware().command(kRight) == 2);
  CHECK(b.firmware().rx_stats().errors[static_cast<int>(RxError::Overlong)] == 1);
}

TEST_CASE("firmware: reset command brakes, re-announces, clears counts") {
  HostBoard b;
  send(b, "s 300 300\r");
  b.advance(1000);
  b.wheel_advance(kLeft, 40);
  b.advance(50000);
  CHECK(b.firmware().encoder(kLeft).count() == 40);
  b.read_tx_string();
  send(b, "r\r");
  b.advance(50000);
  CHECK(b.resets() == 1);
  CHECK(b.firmware().drive_state() == DriveState::Idle);
  CHECK(b.firmware().encoder(kLeft).count() == 0);
  CHECK(b.motor(kLeft).pwm == 255);
  CHECK_FALSE(b.motor(kLeft).ina);
  const std::string out = b.read_tx_string();
  CHECK(lines_with_tag(out, 'v').size() == 1);
}

TEST_CASE("firmware: encoders, ultrasonic, IMU and battery reach their lines") {
  HostBoard b;
  b.wheel_advance(kLeft, 8400);
  b.wheel_advance(kRight, -100);
  b.set_echo_us(1740);  // 30 cm
  Quaternion q;
  q.x = -0.68f;
  q.y = -0.47f;
  q.z = -0.4f;
  q.w = 0.4f;
  b.set_imu(q);
  b.set_battery_volts(12.6);
  b.advance(300000);
  std::string acc;
  CHECK(fields(last_line(b, 'e', acc)) == std::vector<std::string>{"e", "8400", "-100"});
  CHECK(fields(last_line(b, 'u', acc)) == std::vector<std::string>{"u", "30"});
  CHECK(fields(last_line(b, 'i', acc)) == std::vector<std::string>{"i", "-0.6800", "-0.4700", "-0.4000", "0.4000"});
  const double volts = std::strtod(fields(last_line(b, 'b', acc))[1].c_str(), nullptr);
  CHECK(volts == doctest::Approx(12.6).epsilon(0.005));
  // Triggers are at least 60 ms apart: 300 ms -> at most 6.
  CHECK(b.triggers() <= 6);
  CHECK(b.triggers() >= 5);
  // No echo -> 0.
  b.set_echo_us(0);
  b.advance(200000);
  acc.clear();
  CHECK(fields(last_line(b, 'u', acc)) == std::vector<std::string>{"u", "0"});
  // A corrupt IMU sample is not reported; a silent IMU stops the `i` line.
  Quaternion bad;
  bad.x = std::nanf("");
  b.set_imu(bad);
  b.advance(200000);
  acc.clear();
  CHECK(fields(last_line(b, 'i', acc))[1] == "-0.6800");
  b.clear_imu();
  b.advance(1500000);
  b.read_tx_string();
  b.advance(200000);
  acc.clear();
  CHECK(last_line(b, 'i', acc).empty());
  CHECK(b.firmware().diag(b.now()).imu_ok == 0);
}

TEST_CASE("firmware: illegal encoder transitions show up in the d line") {
  HostBoard b;
  b.encoder_edge(kRight, true, true);  // 00 -> 11
  b.advance(1100000);
  std::string acc;
  const auto d = fields(last_line(b, 'd', acc));
  REQUIRE(d.size() == 9);
  CHECK(d[4] == "0");
  CHECK(d[5] == "1");
}

TEST_CASE("firmware: book-compatible 2X decoding and 8-bit command range by config") {
  Config c;
  c.encoder_mode = EncoderMode::X2;
  c.command_max = 255;
  HostBoard b(c);
  b.wheel_advance(kLeft, 8400);
  send(b, "s 255 -128\r");
  b.advance(50000);
  CHECK(b.firmware().encoder(kLeft).count() == 4200);
  CHECK(b.motor(kLeft).pwm == 255);
  CHECK(b.motor(kRight).pwm == 128);
  send(b, "s 256 0\r");
  b.advance(1000);
  CHECK(b.firmware().rx_stats().errors[static_cast<int>(RxError::OutOfRange)] == 1);
}

TEST_CASE("firmware: config is sanitised") {
  Config c;
  c.status_rate_hz = 0;
  c.watchdog_ms = 0;
  c.command_max = 1000000;
  c.ultrasonic_period_ms = 1;
  const Config s = sanitize(c);
  CHECK(s.status_rate_hz == 1);
  CHECK(s.watchdog_ms == 20);
  CHECK(s.command_max == 9999);
  CHECK(s.ultrasonic_period_ms == 60);
}
