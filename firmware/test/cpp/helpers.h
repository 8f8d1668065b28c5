// Shared helpers of the C++ unit tests.
#ifndef CHEFBOT_TEST_HELPERS_H
#define CHEFBOT_TEST_HELPERS_H

#include <string>
#include <vector>

#include "../../core/command_parser.h"

namespace testing {

// protocol_vectors.txt escapes: \t \r \n \\ \xHH.
std::string unescape(const std::string& s);
std::vector<std::string> split(const std::string& s, const std::string& sep);

struct Vector {
  int line_no;
  std::string kind;
  std::vector<std::string> cols;
};
std::vector<Vector> load_vectors();

// Feeds bytes to the parser and renders the events like the vectors file.
std::string parse_events(chefbot::CommandParser& p, const std::string& bytes);

// Splits board output into lines (each keeps its '\n').
std::vector<std::string> lines_of(const std::string& out);
// Lines whose tag is `tag`.
std::vector<std::string> lines_with_tag(const std::string& out, char tag);
// Tab-separated fields of a line, without '\n' and without the checksum token.
std::vector<std::string> fields(const std::string& line);
// True when the line ends in a correct "\t*HH\n".
bool checksum_ok(const std::string& line);

}  // namespace testing

#endif
