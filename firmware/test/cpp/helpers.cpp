#include "helpers.h"

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <stdexcept>

#include "../../core/crc8.h"

namespace testing {

std::string unescape(const std::string& s) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] != '\\') {
      out += s[i];
      continue;
    }
    if (i + 1 >= s.size()) throw std::runtime_error("dangling backslash in " + s);
    const char n = s[++i];
    if (n == 't') out += '\t';
    else if (n == 'r') out += '\r';
    else if (n == 'n') out += '\n';
    else if (n == '\\') out += '\\';
    else if (n == 'x' && i + 2 < s.size() + 0) {
      out += static_cast<char>(std::strtol(s.substr(i + 1, 2).c_str(), nullptr, 16));
      i += 2;
    } else {
      throw std::runtime_error("bad escape in " + s);
    }
  }
  return out;
}

std::vector<std::string> split(const std::string& s, const std::string& sep) {
  std::vector<std::string> out;
  size_t start = 0;
  for (;;) {
    const size_t pos = s.find(sep, start);
    if (pos == std::string::npos) {
      out.push_back(s.substr(start));
      return out;
    }
    out.push_back(s.substr(start, pos - start));
    start = pos + sep.size();
  }
}

std::vector<Vector> load_vectors() {
  std::ifstream in(CHEFBOT_VECTORS_PATH);
  if (!in) throw std::runtime_error("cannot open " CHEFBOT_VECTORS_PATH);
  std::vector<Vector> out;
  std::string line;
  int no = 0;
  while (std::getline(in, line)) {
    ++no;
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> cols = split(line, "\t");
    Vector v;
    v.line_no = no;
    v.kind = cols[0];
    v.cols.assign(cols.begin() + 1, cols.end());
    out.push_back(v);
  }
  return out;
}

std::string parse_events(chefbot::CommandParser& p, const std::string& bytes) {
  std::string out;
  for (unsigned char c : bytes) {
    chefbot::Command cmd;
    const chefbot::RxEvent ev = p.push(c, cmd);
    std::string e;
    switch (ev) {
      case chefbot::RxEvent::None: continue;
      case chefbot::RxEvent::Empty: e = "empty"; break;
      case chefbot::RxEvent::Reset: e = "r"; break;
      case chefbot::RxEvent::Speed: e = "s " + std::to_string(cmd.left) + " " + std::to_string(cmd.right); break;
      case chefbot::RxEvent::Error: e = std::string("error ") + chefbot::rx_error_name(cmd.error); break;
    }
    if (!out.empty()) out += "; ";
    out += e;
  }
  return out.empty() ? "none" : out;
}

std::vector<std::string> lines_of(const std::string& out) {
  std::vector<std::string> lines;
  size_t start = 0;
  for (;;) {
    const size_t nl = out.find('\n', start);
    if (nl == std::string::npos) break;
    lines.push_back(out.substr(start, nl - start + 1));
    start = nl + 1;
  }
  return lines;
}

std::vector<std::string> lines_with_tag(const std::string& out, char tag) {
  std::vector<std::string> r;
  for (const std::string& l : lines_of(out))
    if (!l.empty() && l[0] == tag) r.push_back(l);
  return r;
}

std::vector<std::string> fields(const std::string& line) {
  std::string body = line;
  if (!body.empty() && body.back() == '\n') body.pop_back();
  std::vector<std::string> f = split(body, "\t");
  if (!f.empty() && !f.back().empty() && f.back()[0] == '*') f.pop_back();
  return f;
}

bool checksum_ok(const std::string& line) {
  const size_t n = line.size();
  if (n < 6 || line[n - 1] != '\n' || line[n - 5] != '\t' || line[n - 4] != '*') return false;
  char want[3];
  std::snprintf(want, sizeof(want), "%02X", chefbot::crc8(line.data(), n - 5));
  return line.compare(n - 3, 2, want) == 0;
}

}  // namespace testing
