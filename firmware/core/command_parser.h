// Incremental parser for PC->board commands (see PROTOCOL.md):
//   "s <left> <right>"  motor command, integers in +-command_max
//   "r"                 reset request
// terminated by '\r', '\n' or "\r\n", optionally followed by " *HH" (CRC-8 of
// the bytes before the blank that precedes '*').
//
// Bytes arrive one at a time, possibly split anywhere across reads. The line
// buffer is fixed; anything that does not fit, or is not printable ASCII, is
// discarded up to the next terminator and counted, so no input can overflow
// it or make the parser accept a half-received command.
#ifndef CHEFBOT_CORE_COMMAND_PARSER_H
#define CHEFBOT_CORE_COMMAND_PARSER_H

#include <stddef.h>
#include <stdint.h>

namespace chefbot {

enum class RxEvent : uint8_t {
  None,    // no complete line yet
  Empty,   // blank line (ignored, not an error: "\r\n" pairs are folded before)
  Speed,   // valid "s" command in Command::left/right
  Reset,   // valid "r" command
  Error,   // rejected line, reason in Command::error
};

enum class RxError : uint8_t {
  None = 0,
  Overlong,        // line longer than the buffer
  BadChar,         // byte outside printable ASCII / tab
  UnknownCommand,  // first token is not "s" or "r"
  MissingField,    // too few arguments
  ExtraField,      // too many arguments
  BadNumber,       // argument is not a decimal integer ("nan", "1.5", "0x10")
  OutOfRange,      // integer beyond +-command_max (incl. "99999999999")
  BadChecksum,     // "*HH" token malformed or CRC mismatch
  Count
};

const char* rx_error_name(RxError e);

struct Command {
  RxEvent event = RxEvent::None;
  RxError error = RxError::None;
  int32_t left = 0;
  int32_t right = 0;
  bool had_checksum = false;
};

struct RxStats {
  uint32_t ok = 0;     // accepted commands
  uint32_t empty = 0;  // blank lines
  uint32_t errors[static_cast<size_t>(RxError::Count)] = {};
  uint32_t total_errors() const;
};

class CommandParser {
 public:
  // Longest accepted line without terminator. "s -1023 -1023 *HH" is 17
  // bytes; the rest is slack for extra blanks.
  static const size_t kMaxLine = 40;

  explicit CommandParser(int32_t command_max = 1023);

  // Feed one received byte. Returns the event completed by this byte (and
  // fills `out`), or RxEvent::None.
  RxEvent push(uint8_t byte, Command& out);

  void clear();  // drop a partial line (e.g. after a reset)
  const RxStats& stats() const { return stats_; }
  void set_command_max(int32_t m) { command_max_ = m; }

 private:
  RxEvent finish_line(Command& out);
  RxEvent reject(RxError e, Command& out);

  char buf_[kMaxLine];
  size_t len_ = 0;
  bool overlong_ = false;
  bool bad_char_ = false;
  bool last_was_cr_ = false;
  int32_t command_max_;
  RxStats stats_;
};

}  // namespace chefbot

#endif
