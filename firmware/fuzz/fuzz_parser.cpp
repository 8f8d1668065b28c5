// libFuzzer target: the command parser against a straightforward reference
// implementation of PROTOCOL.md written with std::string. Any disagreement,
// out-of-range value, inconsistent counter or memory error is a crash.
#include <stddef.h>
#include <stdint.h>

#include <cstdlib>
#include <string>
#include <vector>

#include "../core/command_parser.h"
#include "../core/crc8.h"

using namespace chefbot;

namespace {

struct Ev {
  RxEvent event;
  RxError error;
  int32_t left, right;
};

bool is_digit_str(const std::string& s) {
  size_t i = (!s.empty() && (s[0] == '+' || s[0] == '-')) ? 1 : 0;
  if (i == s.size()) return false;
  for (; i < s.size(); ++i)
    if (s[i] < '0' || s[i] > '9') return false;
  return true;
}

int hexv(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

Ev reference_line(const std::string& line, bool overlong, int32_t max) {
  Ev e{RxEvent::Error, RxError::None, 0, 0};
  if (overlong) return e.error = RxError::Overlong, e;
  for (unsigned char c : line)
    if ((c < 0x20 && c != '\t') || c > 0x7E) return e.error = RxError::BadChar, e;
  std::vector<std::string> tok;
  std::vector<size_t> ends;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    if (i == line.size()) break;
    size_t b = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
    tok.push_back(line.substr(b, i - b));
    ends.push_back(i);
  }
  if (tok.empty()) return Ev{RxEvent::Empty, RxError::None, 0, 0};
  if (tok.size() > 1 && tok.back()[0] == '*') {
    const std::string& t = tok.back();
    if (t.size() != 3 || hexv(t[1]) < 0 || hexv(t[2]) < 0) return e.error = RxError::BadChecksum, e;
    if (crc8(line.data(), ends[ends.size() - 2]) != hexv(t[1]) * 16 + hexv(t[2]))
      return e.error = RxError::BadChecksum, e;
    tok.pop_back();
  }
  if (tok[0] != "s" && tok[0] != "r") return e.error = RxError::UnknownCommand, e;
  if (tok[0] == "r") {
    if (tok.size() > 1) return e.error = RxError::ExtraField, e;
    return Ev{RxEvent::Reset, RxError::None, 0, 0};
  }
  if (tok.size() < 3) return e.error = RxError::MissingField, e;
  if (tok.size() > 3) return e.error = RxError::ExtraField, e;
  int32_t v[2];
  for (int k = 0; k < 2; ++k) {
    if (!is_digit_str(tok[1 + k])) return e.error = RxError::BadNumber, e;
    const std::string& s = tok[1 + k];
    size_t d = (s[0] == '+' || s[0] == '-') ? 1 : 0;
    while (d + 1 < s.size() && s[d] == '0') ++d;  // leading zeros
    if (s.size() - d > 5) return e.error = RxError::OutOfRange, e;
    const long n = std::strtol(s.c_str(), nullptr, 10);
    if (n > max || n < -max) return e.error = RxError::OutOfRange, e;
    v[k] = static_cast<int32_t>(n);
  }
  return Ev{RxEvent::Speed, RxError::None, v[0], v[1]};
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 2) return 0;
  const int32_t max = 1 + ((data[0] << 8 | data[1]) % 9999);
  data += 2;
  size -= 2;
  CommandParser p(max);

  std::vector<Ev> ref;
  std::string line;
  bool last_cr = false;
  for (size_t i = 0; i < size; ++i) {
    const char c = static_cast<char>(data[i]);
    if (c == '\r' || c == '\n') {
      const bool folded = c == '\n' && last_cr;
      last_cr = c == '\r';
      if (folded) continue;
      ref.push_back(reference_line(line.substr(0, CommandParser::kMaxLine), line.size() > CommandParser::kMaxLine, max));
      line.clear();
    } else {
      last_cr = false;
      line += c;
    }
  }

  size_t k = 0;
  uint32_t events = 0;
  for (size_t i = 0; i < size; ++i) {
    Command cmd;
    const RxEvent ev = p.push(data[i], cmd);
    if (ev == RxEvent::None) continue;
    ++events;
    if (k >= ref.size()) abort();
    const Ev& r = ref[k++];
    if (ev != r.event || cmd.error != r.error) abort();
    if (ev == RxEvent::Speed) {
      if (cmd.left != r.left || cmd.right != r.right) abort();
      if (cmd.left > max || cmd.left < -max || cmd.right > max || cmd.right < -max) abort();
    }
  }
  if (k != ref.size()) abort();
  const RxStats& s = p.stats();
  if (s.ok + s.empty + s.total_errors() != events) abort();
  return 0;
}
