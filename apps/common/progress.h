// Progress lines for the dn* tools. On a terminal one status line is redrawn
// in place ('\r'); into a file or a pipe (make, CI, a render farm) a plain
// line is written at each 10 % and otherwise at most every few seconds, as
// oiiotool and Blender do, so a log holds a few readable lines instead of
// hundreds of carriage returns.
#pragma once

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>

namespace dn::cli {

// Training runs for hours: off a terminal, a line every 30 s besides each 10 %.
constexpr double kTrainingLineSeconds = 30.0;

// "42s", "3m07s", "2h05m": elapsed and remaining times in progress lines.
inline std::string formatDuration(double seconds) {
  const long s = std::lround(std::max(0.0, seconds));
  char text[32];
  if (s >= 3600)
    std::snprintf(text, sizeof text, "%ldh%02ldm", s / 3600, s % 3600 / 60);
  else if (s >= 60)
    std::snprintf(text, sizeof text, "%ldm%02lds", s / 60, s % 60);
  else
    std::snprintf(text, sizeof text, "%lds", s);
  return text;
}

class Progress {
 public:
  using Clock = std::chrono::steady_clock;

  // Decides by isatty() whether `out` is a terminal.
  explicit Progress(std::FILE* out = stderr, double lineIntervalSeconds = 5.0)
      : Progress(out, ::isatty(::fileno(out)) != 0, lineIntervalSeconds) {}
  Progress(std::FILE* out, bool terminal, double lineIntervalSeconds)
      : out_(out), terminal_(terminal), interval_(lineIntervalSeconds) {}
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;
  ~Progress() { finish(); }

  bool terminal() const { return terminal_; }

  // `text` is the whole status line; `fraction` (0..1) places it in a tenth.
  void update(double fraction, const std::string& text, Clock::time_point now = Clock::now()) {
    if (terminal_) {
      std::fprintf(out_, "\r%s\033[K", text.c_str());
      std::fflush(out_);
      redrawn_ = true;
      return;
    }
    const int tenth = static_cast<int>(std::floor(std::min(std::max(fraction, 0.0), 1.0) * 10));
    const bool due =
        lines_ > 0 && std::chrono::duration<double>(now - lastLine_).count() >= interval_;
    if (tenth <= lastTenth_ && !due) return;
    std::fprintf(out_, "%s\n", text.c_str());
    std::fflush(out_);
    lastTenth_ = std::max(lastTenth_, tenth);
    lastLine_ = now;
    ++lines_;
  }

  // Ends a redrawn terminal line so that the next message starts on its own.
  void finish() {
    if (!redrawn_) return;
    std::fputc('\n', out_);
    std::fflush(out_);
    redrawn_ = false;
  }

 private:
  std::FILE* out_;
  bool terminal_;
  double interval_;
  bool redrawn_ = false;
  int lastTenth_ = -1;
  int lines_ = 0;
  Clock::time_point lastLine_{};
};

}  // namespace dn::cli
