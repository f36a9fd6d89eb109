// Tiny command-line helpers shared by the dn* tools: "--opt value" and
// "--opt=value" forms, typed conversions with one-line errors, and exit codes.
#pragma once

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace dn::cli {

// Exit codes shared by every tool.
constexpr int kExitOk = 0;
constexpr int kExitError = 1;      // bad input, bad arguments, I/O failure
constexpr int kExitThreshold = 2;  // a --maxerror check failed

struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

class Args {
 public:
  Args(int argc, char** argv) : args_(argv + 1, argv + argc) {}

  bool done() const { return pos_ >= args_.size(); }
  const std::string& peek() const { return args_[pos_]; }

  // True (and consumes it) if the next argument is `name` or `name=...`.
  bool flag(const std::string& name) {
    if (done()) return false;
    const std::string& a = args_[pos_];
    if (a == name) {
      ++pos_;
      pending_.reset();
      return true;
    }
    if (a.size() > name.size() && a.compare(0, name.size(), name) == 0 && a[name.size()] == '=') {
      pending_ = a.substr(name.size() + 1);
      ++pos_;
      return true;
    }
    return false;
  }
  bool flag(const std::string& name, const std::string& alias) { return flag(name) || flag(alias); }

  // The value of the option just matched by flag().
  std::string value(const std::string& option) {
    if (pending_) {
      std::string v = *pending_;
      pending_.reset();
      return v;
    }
    if (done()) throw UsageError(option + " needs a value");
    return args_[pos_++];
  }
  int intValue(const std::string& option) { return toInt(option, value(option)); }
  double doubleValue(const std::string& option) { return toDouble(option, value(option)); }
  // The same, refused with one line outside [lo, hi].
  int intValue(const std::string& option, int lo, int hi) {
    return inRange(option, intValue(option), lo, hi);
  }
  double doubleValue(const std::string& option, double lo, double hi) {
    return inRange(option, doubleValue(option), lo, hi);
  }

  std::string positional() { return args_[pos_++]; }

  static int toInt(const std::string& option, const std::string& text) {
    try {
      std::size_t used = 0;
      int v = std::stoi(text, &used);
      if (used == text.size()) return v;
    } catch (const std::exception&) {
    }
    throw UsageError(option + ": '" + text + "' is not an integer");
  }
  // Finite numbers only: "inf" and "nan" would reach the output as non-finite pixels.
  static double toDouble(const std::string& option, const std::string& text) {
    double v = 0;
    try {
      std::size_t used = 0;
      v = std::stod(text, &used);
      if (used != text.size()) v = NAN;
    } catch (const std::exception&) {
      v = NAN;
    }
    if (std::isfinite(v)) return v;
    throw UsageError(option + ": '" + text + "' is not a finite number");
  }
  template <class T>
  static T inRange(const std::string& option, T v, T lo, T hi) {
    if (v >= lo && v <= hi) return v;
    throw UsageError(option + " must be between " + numberText(lo) + " and " + numberText(hi) +
                     ", got " + numberText(v));
  }

 private:
  static std::string numberText(int v) { return std::to_string(v); }
  static std::string numberText(double v) {  // 1e-12, 0.5, 1e+06
    char text[32];
    std::snprintf(text, sizeof text, "%g", v);
    return text;
  }
  std::vector<std::string> args_;
  std::size_t pos_ = 0;
  std::optional<std::string> pending_;
};

inline std::vector<std::string> splitList(const std::string& text, char sep = ',') {
  std::vector<std::string> out;
  std::size_t start = 0;
  while (start <= text.size()) {
    auto end = text.find(sep, start);
    if (end == std::string::npos) end = text.size();
    if (end > start) out.push_back(text.substr(start, end - start));
    start = end + 1;
  }
  return out;
}

// A list of integers "4,16,64", each in [lo, hi]; an empty list is refused.
inline std::vector<int> intList(const std::string& option, const std::string& text, int lo,
                                int hi) {
  std::vector<int> out;
  for (const auto& item : splitList(text))
    out.push_back(Args::inRange(option, Args::toInt(option, item), lo, hi));
  if (out.empty()) throw UsageError(option + " needs a comma-separated list of numbers");
  return out;
}

}  // namespace dn::cli
