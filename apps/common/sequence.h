// Frame sequences as oiiotool spells them: "render.####.exr" or "render.%04d.exr".
#pragma once

#include <algorithm>
#include <filesystem>
#include <regex>
#include <string>
#include <utility>
#include <vector>

namespace dn::cli {

struct FramePattern {
  std::string prefix, suffix;
  int padding = 0;  // 0: not a pattern
};

inline FramePattern parseFramePattern(const std::string& path) {
  static const std::regex printfStyle(R"(^(.*)%0?(\d*)d(.*)$)");
  std::smatch m;
  if (std::regex_match(path, m, printfStyle))
    return {m[1], m[3], m[2].length() ? std::stoi(m[2]) : 1};
  auto first = path.find('#');
  if (first == std::string::npos) return {};
  auto last = path.find_first_not_of('#', first);
  if (last == std::string::npos) last = path.size();
  return {path.substr(0, first), path.substr(last), static_cast<int>(last - first)};
}

inline std::string frameName(const FramePattern& p, int frame) {
  std::string number = std::to_string(frame);
  if (static_cast<int>(number.size()) < p.padding) number.insert(0, p.padding - number.size(), '0');
  return p.prefix + number + p.suffix;
}

// Existing files matching a pattern, as (frame number, path), in frame order.
inline std::vector<std::pair<int, std::string>> findFrames(const FramePattern& p) {
  namespace fs = std::filesystem;
  fs::path prefix(p.prefix);
  fs::path dir = prefix.parent_path().empty() ? fs::path(".") : prefix.parent_path();
  const std::string stem = prefix.filename().string();
  std::vector<std::pair<int, std::string>> frames;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if (name.size() <= stem.size() + p.suffix.size() || name.rfind(stem, 0) != 0 ||
        name.compare(name.size() - p.suffix.size(), p.suffix.size(), p.suffix) != 0)
      continue;
    std::string digits = name.substr(stem.size(), name.size() - stem.size() - p.suffix.size());
    if (digits.empty() || !std::all_of(digits.begin(), digits.end(), ::isdigit)) continue;
    frames.emplace_back(std::stoi(digits), (prefix.parent_path() / name).string());
  }
  std::sort(frames.begin(), frames.end());
  return frames;
}

}  // namespace dn::cli
