#include "command_parser.h"

#include "crc8.h"

namespace chefbot {

namespace {

struct Token {
  size_t begin;
  size_t end;
};

bool is_blank(char c) { return c == ' ' || c == '\t'; }

int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

enum class NumResult { Ok, Bad, Range };

// Strict decimal integer: optional sign, 1+ digits, nothing else. Magnitude is
// accumulated with a cap so "99999999999" reports Range instead of wrapping.
NumResult parse_int(const char* s, size_t n, int32_t limit, int32_t& out) {
  size_t i = 0;
  bool negative = false;
  if (i < n && (s[i] == '+' || s[i] == '-')) {
    negative = s[i] == '-';
    ++i;
  }
  if (i == n) return NumResult::Bad;
  uint32_t magnitude = 0;
  bool too_big = false;
  for (; i < n; ++i) {
    if (s[i] < '0' || s[i] > '9') return NumResult::Bad;
    if (!too_big) {
      magnitude = magnitude * 10u + static_cast<uint32_t>(s[i] - '0');
      if (magnitude > static_cast<uint32_t>(limit)) too_big = true;
    }
  }
  if (too_big) return NumResult::Range;
  out = negative ? -static_cast<int32_t>(magnitude) : static_cast<int32_t>(magnitude);
  return NumResult::Ok;
}

}  // namespace

const char* rx_error_name(RxError e) {
  switch (e) {
    case RxError::None: return "none";
    case RxError::Overlong: return "overlong";
    case RxError::BadChar: return "bad_char";
    case RxError::UnknownCommand: return "unknown_command";
    case RxError::MissingField: return "missing_field";
    case RxError::ExtraField: return "extra_field";
    case RxError::BadNumber: return "bad_number";
    case RxError::OutOfRange: return "out_of_range";
    case RxError::BadChecksum: return "bad_checksum";
    case RxError::Count: break;
  }
  return "?";
}

uint32_t RxStats::total_errors() const {
  uint32_t sum = 0;
  for (size_t i = 0; i < static_cast<size_t>(RxError::Count); ++i) sum += errors[i];
  return sum;
}

CommandParser::CommandParser(int32_t command_max) : buf_(), command_max_(command_max) {}

void CommandParser::clear() {
  len_ = 0;
  overlong_ = false;
  bad_char_ = false;
  last_was_cr_ = false;
}

RxEvent CommandParser::push(uint8_t byte, Command& out) {
  const char c = static_cast<char>(byte);
  if (c == '\r' || c == '\n') {
    // The second byte of "\r\n" ends nothing: the '\r' already did.
    const bool folded = (c == '\n') && last_was_cr_;
    last_was_cr_ = (c == '\r');
    if (folded) return RxEvent::None;
    const RxEvent ev = finish_line(out);
    len_ = 0;
    overlong_ = false;
    bad_char_ = false;
    return ev;
  }
  last_was_cr_ = false;
  if (byte < 0x20u && c != '\t') {
    bad_char_ = true;
  } else if (byte > 0x7Eu) {
    bad_char_ = true;
  }
  if (len_ < kMaxLine) {
    buf_[len_++] = c;
  } else {
    overlong_ = true;
  }
  return RxEvent::None;
}

RxEvent CommandParser::reject(RxError e, Command& out) {
  ++stats_.errors[static_cast<size_t>(e)];
  out = Command();
  out.event = RxEvent::Error;
  out.error = e;
  return RxEvent::Error;
}

RxEvent CommandParser::finish_line(Command& out) {
  if (overlong_) return reject(RxError::Overlong, out);
  if (bad_char_) return reject(RxError::BadChar, out);

  // The first three tokens are all a valid line can use; the last two are
  // tracked separately because the checksum is whatever token comes last.
  Token tok[3] = {};
  Token last = {0, 0};
  Token before_last = {0, 0};
  size_t count = 0;
  size_t i = 0;
  while (i < len_) {
    while (i < len_ && is_blank(buf_[i])) ++i;
    if (i == len_) break;
    const size_t begin = i;
    while (i < len_ && !is_blank(buf_[i])) ++i;
    const Token t = {begin, i};
    if (count < 3) tok[count] = t;
    before_last = last;
    last = t;
    ++count;
  }
  if (count == 0) {
    ++stats_.empty;
    out = Command();
    out.event = RxEvent::Empty;
    return RxEvent::Empty;
  }

  bool had_checksum = false;
  if (count > 1 && buf_[last.begin] == '*') {
    if (last.end - last.begin != 3) return reject(RxError::BadChecksum, out);
    const int hi = hex_value(buf_[last.begin + 1]);
    const int lo = hex_value(buf_[last.begin + 2]);
    if (hi < 0 || lo < 0) return reject(RxError::BadChecksum, out);
    const uint8_t want = static_cast<uint8_t>((hi << 4) | lo);
    if (crc8(buf_, before_last.end) != want) return reject(RxError::BadChecksum, out);
    had_checksum = true;
    --count;
  }

  const Token& cmd = tok[0];
  const size_t cmd_len = cmd.end - cmd.begin;
  const char name = buf_[cmd.begin];
  if (cmd_len != 1 || (name != 's' && name != 'r')) return reject(RxError::UnknownCommand, out);

  if (name == 'r') {
    if (count > 1) return reject(RxError::ExtraField, out);
    ++stats_.ok;
    out = Command();
    out.event = RxEvent::Reset;
    out.had_checksum = had_checksum;
    return RxEvent::Reset;
  }

  if (count < 3) return reject(RxError::MissingField, out);
  if (count > 3) return reject(RxError::ExtraField, out);
  int32_t values[2] = {0, 0};
  for (int k = 0; k < 2; ++k) {
    const Token& t = tok[1 + k];
    const NumResult r = parse_int(buf_ + t.begin, t.end - t.begin, command_max_, values[k]);
    if (r == NumResult::Bad) return reject(RxError::BadNumber, out);
    if (r == NumResult::Range) return reject(RxError::OutOfRange, out);
  }
  ++stats_.ok;
  out = Command();
  out.event = RxEvent::Speed;
  out.left = values[0];
  out.right = values[1];
  out.had_checksum = had_checksum;
  return RxEvent::Speed;
}

}  // namespace chefbot

// Out-of-line definition: C++11 needs one when the constant is odr-used.
const size_t chefbot::CommandParser::kMaxLine;
