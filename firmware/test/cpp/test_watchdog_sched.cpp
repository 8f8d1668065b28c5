#include <doctest/doctest.h>

#include "../../core/scheduler.h"
#include "../../core/watchdog.h"

using namespace chefbot;

TEST_CASE("watchdog: idle until fed, trips exactly at the timeout, once") {
  CommandWatchdog w(500000);
  CHECK(w.state() == DriveState::Idle);
  CHECK_FALSE(w.check(10000000));
  w.feed(1000);
  CHECK(w.motors_enabled());
  CHECK_FALSE(w.check(1000 + 499999));
  CHECK(w.motors_enabled());
  CHECK(w.check(1000 + 500000));
  CHECK(w.state() == DriveState::Timeout);
  CHECK_FALSE(w.check(1000 + 600000));
  CHECK(w.trips() == 1);
  w.feed(2000000);
  CHECK(w.state() == DriveState::Run);
}

TEST_CASE("watchdog: feeding keeps it running; works across micros() wrap") {
  CommandWatchdog w(500000);
  uint32_t t = 0xFFFFFFFFu - 1000000u;
  w.feed(t);
  for (int i = 0; i < 100; ++i) {
    t += 400000;  // crosses 2^32
    CHECK_FALSE(w.check(t));
    w.feed(t);
  }
  CHECK(w.check(t + 500000));
}

TEST_CASE("scheduler: fixed rate without drift under loop jitter") {
  PeriodicScheduler s(33333);
  uint32_t t = 0;
  s.start(t);
  int cycles = 0;
  uint32_t seed = 1;
  // 10 s of a loop whose pass takes 100..1600 us.
  while (t < 10000000u) {
    if (s.due(t)) ++cycles;
    seed = seed * 1103515245u + 12345u;
    t += 100 + (seed >> 16) % 1500;
  }
  CHECK(cycles >= 300);
  CHECK(cycles <= 301);
  CHECK(s.overruns() == 0);
  CHECK(s.last_interval_us() >= 33333);
  CHECK(s.last_interval_us() < 33333 + 1600);
}

TEST_CASE("scheduler: a long stall drops missed cycles instead of bursting") {
  PeriodicScheduler s(10000);
  s.start(0);
  CHECK(s.due(0));
  CHECK_FALSE(s.due(5000));
  CHECK(s.due(95000));  // 8 periods late
  CHECK(s.overruns() >= 8);
  CHECK_FALSE(s.due(96000));
  CHECK(s.due(105000));
}

TEST_CASE("scheduler: across the micros() wrap") {
  PeriodicScheduler s(10000);
  uint32_t t = 0xFFFFFFFFu - 25000u;
  s.start(t);
  int n = 0;
  for (int i = 0; i < 1000; ++i, t += 100)
    if (s.due(t)) ++n;
  CHECK(n == 10);
  CHECK(s.overruns() == 0);
}

TEST_CASE("tx pacer: drains at the line rate") {
  TxPacer p(256, 11520);
  CHECK(p.space(0) == 256);
  p.wrote(256, 0);
  CHECK(p.space(0) == 0);
  CHECK(p.space(11000) == 126);  // 11 ms at 11520 B/s = 126.7 bytes sent
  CHECK(p.space(22300) == 256);  // 256 bytes take 22.2 ms
  p.wrote(256, 1000000);  // buffer was empty again long before
  const uint32_t after_10ms = p.space(1010000);
  CHECK(after_10ms >= 114);  // 10 ms at 11520 B/s = 115.2 bytes
  CHECK(after_10ms <= 116);
}
