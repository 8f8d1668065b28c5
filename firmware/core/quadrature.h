// Quadrature decoder for one encoder, fed with the (A, B) pin levels after
// every edge (from the pin-change interrupt on the board, or the simulator).
//
// State s = (A << 1) | B. Forward is the Gray sequence 00 -> 01 -> 11 -> 10 ->
// 00 (B leads A); backward is the reverse. In X4 mode every legal transition
// counts; a jump that changes both bits at once (a missed edge) is counted as
// illegal and leaves the count unchanged, because its direction is unknowable.
// X2 and X1 look only at edges of A and take the direction from the level of
// B at that moment, so they stay correct when only A raises interrupts.
#ifndef CHEFBOT_CORE_QUADRATURE_H
#define CHEFBOT_CORE_QUADRATURE_H

#include <stdint.h>

#include "config.h"

namespace chefbot {

class QuadratureDecoder {
 public:
  explicit QuadratureDecoder(EncoderMode mode = EncoderMode::X4, bool invert = false);

  // Sets the reference state without counting (call once at start-up with
  // the current pin levels).
  void prime(bool a, bool b);
  // Called on every edge; safe from an ISR (no locks, bounded work).
  void update(bool a, bool b);

  // Cumulative count, wrapping modulo 2^32 like the PC side expects of a
  // 32-bit counter.
  int32_t count() const { return static_cast<int32_t>(count_); }
  void set_count(int32_t c) { count_ = static_cast<uint32_t>(c); }
  uint32_t illegal() const { return illegal_; }
  EncoderMode mode() const { return mode_; }
  void configure(EncoderMode mode, bool invert);

 private:
  // volatile: written in the ISR, read by the main loop. 32-bit aligned
  // accesses are atomic on Cortex-M.
  volatile uint32_t count_ = 0;
  volatile uint32_t illegal_ = 0;
  volatile uint8_t state_ = 0;
  EncoderMode mode_;
  bool invert_;
};

}  // namespace chefbot

#endif
