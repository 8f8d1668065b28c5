#include "quadrature.h"

namespace chefbot {

namespace {

// Index (previous << 2) | current. +1 forward, -1 backward, 0 no change,
// 2 illegal (both bits changed).
const int8_t kX4Table[16] = {
    // to:  00  01  10  11
    0, +1, -1, 2,   // from 00
    -1, 0, 2, +1,   // from 01
    +1, 2, 0, -1,   // from 10
    2, -1, +1, 0,   // from 11
};

}  // namespace

QuadratureDecoder::QuadratureDecoder(EncoderMode mode, bool invert) : mode_(mode), invert_(invert) {}

void QuadratureDecoder::configure(EncoderMode mode, bool invert) {
  mode_ = mode;
  invert_ = invert;
}

void QuadratureDecoder::prime(bool a, bool b) {
  state_ = static_cast<uint8_t>((a ? 2u : 0u) | (b ? 1u : 0u));
}

void QuadratureDecoder::update(bool a, bool b) {
  const uint8_t prev = state_;
  const uint8_t cur = static_cast<uint8_t>((a ? 2u : 0u) | (b ? 1u : 0u));
  state_ = cur;
  int step = 0;
  if (mode_ == EncoderMode::X4) {
    step = kX4Table[(prev << 2) | cur];
    if (step == 2) {
      illegal_ = illegal_ + 1u;
      return;
    }
  } else {
    const bool a_prev = (prev & 2u) != 0;
    if (a_prev == a) return;  // not an edge of A
    if (mode_ == EncoderMode::X1 && !a) return;
    // After an A edge moving forward, A and B are equal (01->11, 10->00).
    step = (a == b) ? +1 : -1;
  }
  if (step == 0) return;
  if (invert_) step = -step;
  count_ = count_ + static_cast<uint32_t>(static_cast<int32_t>(step));
}

}  // namespace chefbot
