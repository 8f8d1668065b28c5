// Golden strings from protocol_vectors.txt, the file the Python side reads too.
#include <doctest/doctest.h>

#include <cmath>
#include <cstdlib>
#include <string>

#include "../../core/crc8.h"
#include "../../core/line_format.h"
#include "helpers.h"

using namespace chefbot;
using testing::split;
using testing::unescape;

namespace {

std::string format_values(const std::string& spec, bool crc) {
  const std::vector<std::string> v = split(spec, " ");
  LineBuilder b;
  const char tag = v[0][0];
  auto i32 = [&](size_t k) { return static_cast<int32_t>(std::strtol(v[k].c_str(), nullptr, 10)); };
  auto u32 = [&](size_t k) { return static_cast<uint32_t>(std::strtoul(v[k].c_str(), nullptr, 10)); };
  auto f = [&](size_t k) { return std::strtod(v[k].c_str(), nullptr); };
  size_t n = 0;
  switch (tag) {
    case 'b': n = format_battery(b, static_cast<uint32_t>(std::lround(f(1) * 1000.0)), crc); break;
    case 't': n = format_time(b, u32(1), static_cast<uint32_t>(std::lround(f(2) * 1e6)), crc); break;
    case 'e': n = format_encoders(b, i32(1), i32(2), crc); break;
    case 'u': n = format_ultrasonic(b, u32(1), crc); break;
    case 's': {
      DriveState st = DriveState::Idle;
      if (v[3] == "run") st = DriveState::Run;
      if (v[3] == "timeout") st = DriveState::Timeout;
      REQUIRE(std::string(drive_state_name(st)) == v[3]);
      n = format_speed(b, i32(1), i32(2), st, crc);
      break;
    }
    case 'i': {
      Quaternion q;
      q.x = static_cast<float>(f(1));
      q.y = static_cast<float>(f(2));
      q.z = static_cast<float>(f(3));
      q.w = static_cast<float>(f(4));
      n = format_imu(b, q, crc);
      break;
    }
    case 'v': {
      Config c;
      REQUIRE(i32(1) == kProtocolVersion);
      REQUIRE(v[2] == kFirmwareVersion);
      c.status_rate_hz = u32(3);
      c.watchdog_ms = u32(4);
      c.encoder_mode = static_cast<EncoderMode>(u32(5));
      c.command_max = i32(6);
      n = format_hello(b, c, crc);
      break;
    }
    case 'd': {
      DiagCounters d;
      d.rx_ok = u32(1);
      d.rx_errors = u32(2);
      d.watchdog_trips = u32(3);
      d.encoder_illegal_left = u32(4);
      d.encoder_illegal_right = u32(5);
      d.tx_dropped_lines = u32(6);
      d.schedule_overruns = u32(7);
      d.imu_ok = u32(8);
      n = format_diag(b, d, crc);
      break;
    }
    default: FAIL("unknown tag in vector: " << spec);
  }
  return std::string(b.data(), n);
}

}  // namespace

TEST_CASE("protocol vectors: file loads and has every kind") {
  const auto vs = testing::load_vectors();
  int counts[5] = {};
  for (const auto& v : vs) {
    if (v.kind == "crc") ++counts[0];
    if (v.kind == "rx") ++counts[1];
    if (v.kind == "tx") ++counts[2];
    if (v.kind == "plain") ++counts[3];
    if (v.kind == "book") ++counts[4];
    CHECK_MESSAGE(v.cols.size() == 2, "line " << v.line_no);
  }
  for (int c : counts) CHECK(c > 0);
}

TEST_CASE("protocol vectors: CRC-8") {
  for (const auto& v : testing::load_vectors()) {
    if (v.kind != "crc") continue;
    const std::string data = unescape(v.cols[0]);
    const unsigned want = static_cast<unsigned>(std::strtoul(v.cols[1].c_str(), nullptr, 16));
    CHECK_MESSAGE(crc8(data.data(), data.size()) == want, "line " << v.line_no);
  }
}

TEST_CASE("protocol vectors: PC->board commands") {
  for (const auto& v : testing::load_vectors()) {
    if (v.kind != "rx") continue;
    CommandParser p(1023);
    CHECK_MESSAGE(testing::parse_events(p, unescape(v.cols[0])) == v.cols[1], "line " << v.line_no << ": " << v.cols[0]);
  }
}

TEST_CASE("protocol vectors: board->PC lines") {
  for (const auto& v : testing::load_vectors()) {
    if (v.kind != "tx" && v.kind != "plain") continue;
    const std::string got = format_values(v.cols[0], v.kind == "tx");
    CHECK_MESSAGE(got == unescape(v.cols[1]), "line " << v.line_no << ": " << v.cols[0]);
    if (v.kind == "tx") CHECK(testing::checksum_ok(got));
  }
}

TEST_CASE("protocol vectors: book lines keep the field order we emit") {
  // The book's lines differ from ours only in precision and trailing fields:
  // the first fields of ours, read as numbers, must equal the book's.
  for (const auto& v : testing::load_vectors()) {
    if (v.kind != "book") continue;
    const auto book = testing::fields(unescape(v.cols[1]));
    const std::string spec = v.cols[0] + (v.cols[0][0] == 's' ? " idle" : "");
    const auto ours = testing::fields(format_values(spec, true));
    REQUIRE(ours.size() >= book.size());
    CHECK(ours[0] == book[0]);
    for (size_t k = 1; k < book.size(); ++k)
      CHECK_MESSAGE(std::strtod(ours[k].c_str(), nullptr) == doctest::Approx(std::strtod(book[k].c_str(), nullptr)),
                    "line " << v.line_no << " field " << k);
  }
}
