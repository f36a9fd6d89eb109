// The shared progress lines: redrawn on a terminal, plain lines at each 10 %
// and every few seconds in a log.
#include <doctest/doctest.h>

#include <algorithm>
#include <cstdio>
#include <string>

#include "common/progress.h"

using dn::cli::Progress;
using namespace std::chrono_literals;

namespace {

// Everything written to a temporary FILE* by `body`.
template <class Body>
std::string captured(Body&& body) {
  std::FILE* file = std::tmpfile();
  REQUIRE(file != nullptr);
  body(file);
  std::string text(static_cast<std::size_t>(std::ftell(file)), '\0');
  std::rewind(file);
  text.resize(std::fread(text.data(), 1, text.size(), file));
  std::fclose(file);
  return text;
}

int lineCount(const std::string& text) {
  return static_cast<int>(std::count(text.begin(), text.end(), '\n'));
}

}  // namespace

TEST_CASE("off a terminal: one plain line per tenth, however many updates") {
  const auto start = Progress::Clock::now();
  const std::string log = captured([&](std::FILE* file) {
    Progress progress(file, false, 5.0);
    for (int step = 0; step <= 1000; ++step)
      progress.update(step / 1000.0, "step " + std::to_string(step), start);
  });
  CHECK(log.find('\r') == std::string::npos);
  CHECK(lineCount(log) == 11);  // 0 %, 10 %, ..., 100 %
  CHECK(log.rfind("step 1000\n") != std::string::npos);
  CHECK(log.find("step 100\n") != std::string::npos);
}

TEST_CASE("off a terminal: a slow tenth still gets a line every interval") {
  const auto start = Progress::Clock::now();
  const std::string log = captured([&](std::FILE* file) {
    Progress progress(file, false, 5.0);
    // 60 updates one second apart, all inside the first tenth.
    for (int s = 0; s < 60; ++s) progress.update(0.05, "t " + std::to_string(s), start + s * 1s);
  });
  CHECK(lineCount(log) == 12);  // at 0, 5, 10, ..., 55 s
  CHECK(log.find("t 5\n") != std::string::npos);
  CHECK(log.find("t 4\n") == std::string::npos);
}

TEST_CASE("on a terminal: one line redrawn in place, ended by finish()") {
  const std::string log = captured([&](std::FILE* file) {
    Progress progress(file, true, 5.0);
    for (int step = 1; step <= 50; ++step)
      progress.update(step / 50.0, "step " + std::to_string(step));
    progress.finish();
    progress.finish();  // a second finish adds nothing
  });
  CHECK(std::count(log.begin(), log.end(), '\r') == 50);
  CHECK(lineCount(log) == 1);
  CHECK(log.back() == '\n');
}

TEST_CASE("durations read as seconds, minutes or hours") {
  CHECK(dn::cli::formatDuration(42.4) == "42s");
  CHECK(dn::cli::formatDuration(187) == "3m07s");
  CHECK(dn::cli::formatDuration(7500) == "2h05m");
  CHECK(dn::cli::formatDuration(-3) == "0s");
}
