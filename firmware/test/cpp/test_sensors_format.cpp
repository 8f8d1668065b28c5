#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <string>

#include "../../core/battery.h"
#include "../../core/line_format.h"
#include "../../core/ultrasonic.h"
#include "helpers.h"

using namespace chefbot;

TEST_CASE("ultrasonic: echo width to cm is the book's us/29/2") {
  CHECK(UltrasonicRanger::width_to_cm(580) == 10);
  CHECK(UltrasonicRanger::width_to_cm(57) == 0);
  CHECK(UltrasonicRanger::width_to_cm(23200) == 400);
  for (uint32_t w = 0; w < 30000; w += 7) CHECK(UltrasonicRanger::width_to_cm(w) == w / 58);
}

TEST_CASE("ultrasonic: trigger spacing, measurement, no-echo and timeout") {
  UltrasonicRanger r(60000, 400);
  uint32_t t = 1000;
  r.restart(t);
  CHECK(r.poll(t));  // first trigger immediately
  CHECK_FALSE(r.poll(t + 100));
  r.echo_edge(true, t + 500);
  r.echo_edge(false, t + 500 + 5800);
  CHECK_FALSE(r.poll(t + 7000));  // result taken, but 60 ms not over
  CHECK(r.distance_cm() == 100);
  CHECK_FALSE(r.poll(t + 59999));
  CHECK(r.poll(t + 60000));  // >= 60 ms between triggers
  t += 60000;
  // No rising edge at all: sensor missing.
  CHECK_FALSE(r.poll(t + 10000));
  CHECK_FALSE(r.poll(t + 10001));
  CHECK(r.distance_cm() == UltrasonicRanger::kNoEcho);
  CHECK(r.poll(t + 60000));
  t += 60000;
  // Echo longer than 400 cm (HC-SR04 holds 38 ms without an obstacle).
  r.echo_edge(true, t + 500);
  CHECK_FALSE(r.poll(t + 500 + 23300));
  CHECK(r.distance_cm() == UltrasonicRanger::kNoEcho);
  r.echo_edge(false, t + 500 + 38000);  // late fall while idle is ignored
  CHECK(r.poll(t + 60000));
  t += 60000;
  // Very close objects are reported at the 2 cm floor, not as "nothing".
  r.echo_edge(true, t + 500);
  r.echo_edge(false, t + 560);
  r.poll(t + 600);
  CHECK(r.distance_cm() == 2);
  CHECK(r.no_echoes() == 2);
}

TEST_CASE("ultrasonic: period below 60 ms is raised to 60 ms") {
  UltrasonicRanger r(10000, 400);
  r.restart(0);
  CHECK(r.poll(0));
  CHECK_FALSE(r.poll(59999));
}

TEST_CASE("battery: divider conversion and filter") {
  BatteryDivider d;  // 47k/10k, 3.3 V, 12 bit
  CHECK(battery_millivolts(0, d) == 0);
  CHECK(battery_millivolts(4095, d) == doctest::Approx(18810).epsilon(0.002));
  // 12.0 V -> 2.105 V at the pin -> raw 2612
  CHECK(battery_millivolts(2612, d) == doctest::Approx(11999).epsilon(0.002));
  CHECK(battery_millivolts(60000, d) == battery_millivolts(4095, d));
  BatteryMonitor m(d);
  m.sample(2612);
  const uint32_t v0 = m.millivolts();
  for (int i = 0; i < 100; ++i) m.sample(2400);
  CHECK(m.millivolts() < v0);
  CHECK(m.millivolts() == doctest::Approx(battery_millivolts(2400, d)).epsilon(0.001));
}

TEST_CASE("format: extremes fit the budgeted lengths exactly") {
  LineBuilder b;
  CHECK(format_battery(b, 0xFFFFFFFFu, true) == kMaxLenBattery);
  CHECK(format_time(b, 0xFFFFFFFFu, 0xFFFFFFFFu, true) == kMaxLenTime);
  CHECK(format_encoders(b, -2147483647 - 1, -2147483647 - 1, true) == kMaxLenEncoders);
  CHECK(format_ultrasonic(b, 400, true) == kMaxLenUltrasonic);
  CHECK(format_speed(b, -9999, -9999, DriveState::Timeout, true) == kMaxLenSpeed);
  Quaternion q;
  q.x = q.y = q.z = q.w = -1.0f;
  CHECK(format_imu(b, q, true) == kMaxLenImu);
  DiagCounters d;
  d.rx_ok = d.rx_errors = d.watchdog_trips = d.encoder_illegal_left = d.encoder_illegal_right = d.tx_dropped_lines =
      d.schedule_overruns = d.imu_ok = 0xFFFFFFFFu;
  CHECK(format_diag(b, d, true) == kMaxLenDiag);
  CHECK(kMaxLenDiag <= LineBuilder::kCapacity);
}

TEST_CASE("format: rounding, signs and non-finite IMU values") {
  LineBuilder b;
  format_battery(b, 12344, false);
  CHECK(std::string(b.data(), b.size()) == "b\t12.34\n");
  format_battery(b, 12345, false);
  CHECK(std::string(b.data(), b.size()) == "b\t12.35\n");
  Quaternion q;
  q.x = -0.00004f;  // rounds to zero: must not print "-0.0000"
  q.y = std::numeric_limits<float>::quiet_NaN();
  q.z = 2.0f;
  q.w = -std::numeric_limits<float>::infinity();
  format_imu(b, q, false);
  CHECK(std::string(b.data(), b.size()) == "i\t0.0000\t0.0000\t1.0000\t-1.0000\n");
  format_time(b, 5, 33333, false);
  CHECK(std::string(b.data(), b.size()) == "t\t5\t0.033\n");
}

TEST_CASE("format: overflowing the builder yields no line, never a cut one") {
  LineBuilder b;
  b.begin('x');
  for (int i = 0; i < 40; ++i) b.add_uint(4000000000u);
  CHECK(b.finish(true) == 0);
  CHECK(b.size() == 0);
}
