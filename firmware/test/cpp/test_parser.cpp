#include <doctest/doctest.h>

#include <string>

#include "../../core/command_parser.h"
#include "../../core/crc8.h"
#include "helpers.h"

using namespace chefbot;
using testing::parse_events;

TEST_CASE("parser: CRC-8/SMBUS check value") { CHECK(crc8("123456789", 9) == 0xF4); }

TEST_CASE("parser: a line split across reads at every position") {
  const std::string line = "s 123 -45\r";
  for (size_t cut = 0; cut <= line.size(); ++cut) {
    CommandParser p;
    std::string ev = parse_events(p, line.substr(0, cut));
    const std::string rest = parse_events(p, line.substr(cut));
    if (cut == line.size()) {
      CHECK(ev == "s 123 -45");
      CHECK(rest == "none");
    } else {
      CHECK(ev == "none");
      CHECK(rest == "s 123 -45");
    }
  }
}

TEST_CASE("parser: \\r\\n split between reads is still one terminator") {
  CommandParser p;
  CHECK(parse_events(p, "s 1 2\r") == "s 1 2");
  CHECK(parse_events(p, "\n") == "none");
  CHECK(parse_events(p, "s 3 4\n") == "s 3 4");
  CHECK(p.stats().empty == 0);
}

TEST_CASE("parser: counts every class and accepted lines") {
  CommandParser p;
  parse_events(p, "s 1 2\rr\r\r x\rs 1\rs 1 2 3\rs a 1\rs 5000 1\rs 1 2 *00\r\x01\r");
  std::string longline(200, 'a');
  parse_events(p, longline + "\r");
  const RxStats& s = p.stats();
  CHECK(s.ok == 2);
  CHECK(s.empty == 1);
  CHECK(s.errors[static_cast<int>(RxError::UnknownCommand)] == 1);
  CHECK(s.errors[static_cast<int>(RxError::MissingField)] == 1);
  CHECK(s.errors[static_cast<int>(RxError::ExtraField)] == 1);
  CHECK(s.errors[static_cast<int>(RxError::BadNumber)] == 1);
  CHECK(s.errors[static_cast<int>(RxError::OutOfRange)] == 1);
  CHECK(s.errors[static_cast<int>(RxError::BadChecksum)] == 1);
  CHECK(s.errors[static_cast<int>(RxError::BadChar)] == 1);
  CHECK(s.errors[static_cast<int>(RxError::Overlong)] == 1);
  CHECK(s.total_errors() == 8);
}

TEST_CASE("parser: the line buffer limit is exact") {
  CommandParser p;
  std::string ok = "s 1 2" + std::string(CommandParser::kMaxLine - 5, ' ');
  REQUIRE(ok.size() == CommandParser::kMaxLine);
  CHECK(parse_events(p, ok + "\r") == "s 1 2");
  CHECK(parse_events(p, ok + " \r") == "error overlong");
}

TEST_CASE("parser: a megabyte without terminator, then a valid line") {
  CommandParser p;
  std::string junk(1 << 20, 's');
  CHECK(parse_events(p, junk) == "none");
  CHECK(parse_events(p, "\rs 9 9\r") == "error overlong; s 9 9");
}

TEST_CASE("parser: every byte value as a one-byte line") {
  for (int c = 0; c < 256; ++c) {
    if (c == '\r' || c == '\n') continue;
    CommandParser p;
    const std::string ev = parse_events(p, std::string(1, static_cast<char>(c)) + "\r");
    if (c == ' ' || c == '\t') {
      CHECK(ev == "empty");
    } else if (c == 'r') {
      CHECK(ev == "r");
    } else if (c == 's') {
      CHECK(ev == "error missing_field");
    } else if (c < 0x20 || c > 0x7E) {
      CHECK(ev == "error bad_char");
    } else {
      CHECK(ev == "error unknown_command");
    }
  }
}

TEST_CASE("parser: configurable command range") {
  CommandParser p(255);
  CHECK(parse_events(p, "s 255 -255\r") == "s 255 -255");
  CHECK(parse_events(p, "s 256 0\r") == "error out_of_range");
}

TEST_CASE("parser: lower-case hex checksum accepted, checksum flag reported") {
  CommandParser p;
  char buf[16];
  const uint8_t c = crc8("s 1 2", 5);
  snprintf(buf, sizeof buf, "s 1 2 *%02x\r", c);
  Command cmd;
  RxEvent last = RxEvent::None;
  for (const char* q = buf; *q; ++q) {
    const RxEvent e = p.push(static_cast<uint8_t>(*q), cmd);
    if (e != RxEvent::None) last = e;
  }
  CHECK(last == RxEvent::Speed);
  CHECK(cmd.had_checksum);
}
