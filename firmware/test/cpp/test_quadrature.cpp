#include <doctest/doctest.h>

#include "../../core/quadrature.h"

using namespace chefbot;

namespace {
// Forward Gray order of (A, B).
const int kSeq[4][2] = {{0, 0}, {0, 1}, {1, 1}, {1, 0}};

int32_t run(QuadratureDecoder& d, int start, int steps) {
  d.prime(kSeq[start][0] != 0, kSeq[start][1] != 0);
  int idx = start;
  const int dir = steps < 0 ? -1 : 1;
  for (int n = 0; n < (steps < 0 ? -steps : steps); ++n) {
    idx = (idx + dir + 4) % 4;
    d.update(kSeq[idx][0] != 0, kSeq[idx][1] != 0);
  }
  return d.count();
}
}  // namespace

TEST_CASE("quadrature X4: all 16 transitions from every state") {
  for (int from = 0; from < 4; ++from) {
    for (int to = 0; to < 4; ++to) {
      QuadratureDecoder d(EncoderMode::X4);
      d.prime(kSeq[from][0] != 0, kSeq[from][1] != 0);
      d.update(kSeq[to][0] != 0, kSeq[to][1] != 0);
      const int diff = (to - from + 4) % 4;
      CAPTURE(from);
      CAPTURE(to);
      if (diff == 0) {
        CHECK(d.count() == 0);
        CHECK(d.illegal() == 0);
      } else if (diff == 1) {
        CHECK(d.count() == 1);
        CHECK(d.illegal() == 0);
      } else if (diff == 3) {
        CHECK(d.count() == -1);
        CHECK(d.illegal() == 0);
      } else {
        CHECK(d.count() == 0);
        CHECK(d.illegal() == 1);
      }
    }
  }
}

TEST_CASE("quadrature X4: full turns both directions, every start state") {
  for (int start = 0; start < 4; ++start) {
    QuadratureDecoder f(EncoderMode::X4);
    CHECK(run(f, start, 8400) == 8400);
    QuadratureDecoder b(EncoderMode::X4);
    CHECK(run(b, start, -8400) == -8400);
    CHECK(f.illegal() == 0);
  }
}

TEST_CASE("quadrature X4: illegal jump keeps state in sync") {
  QuadratureDecoder d(EncoderMode::X4);
  d.prime(false, false);
  d.update(true, true);  // 00 -> 11: missed edge
  CHECK(d.illegal() == 1);
  d.update(true, false);  // 11 -> 10 is forward from the new state
  CHECK(d.count() == 1);
}

TEST_CASE("quadrature X4: inversion") {
  QuadratureDecoder d(EncoderMode::X4, true);
  CHECK(run(d, 0, 100) == -100);
}

TEST_CASE("quadrature X2: counts A edges only, direction from B") {
  for (int start = 0; start < 4; ++start) {
    QuadratureDecoder f(EncoderMode::X2);
    CHECK(run(f, start, 8400) == 4200);
    QuadratureDecoder b(EncoderMode::X2);
    CHECK(run(b, start, -8400) == -4200);
  }
  // Only A is wired to an interrupt: B changes are never seen, direction is
  // still right because it is read from B's level at A's edge.
  QuadratureDecoder d(EncoderMode::X2);
  d.prime(false, true);   // 01
  d.update(true, true);   // A rises with B high: forward
  d.update(false, false); // A falls with B low: forward (skipping 10 is fine)
  CHECK(d.count() == 2);
  d.update(true, false);  // A rises with B low: backward
  CHECK(d.count() == 1);
  CHECK(d.illegal() == 0);
}

TEST_CASE("quadrature X1: rising edges of A only") {
  QuadratureDecoder f(EncoderMode::X1);
  CHECK(run(f, 0, 8400) == 2100);
  QuadratureDecoder b(EncoderMode::X1);
  CHECK(run(b, 0, -8400) == -2100);
}

TEST_CASE("quadrature: 32-bit count wraps like the PC expects") {
  QuadratureDecoder d(EncoderMode::X4);
  d.set_count(2147483647);
  run(d, 0, 1);
  CHECK(d.count() == -2147483647 - 1);
  run(d, 1, -1);
  CHECK(d.count() == 2147483647);
}
