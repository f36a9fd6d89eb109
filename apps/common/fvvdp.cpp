#include "common/fvvdp.h"

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <fmt/format.h>
#include <unistd.h>

#include "dn/io/npy.h"
#include "dn/metrics.h"

namespace dn::cli {
namespace fs = std::filesystem;

namespace {

// Reads ref_N.npy and test_N.npy (height, width, 3, display-encoded) from the
// folder in argv[1] and prints one JOD per line.
constexpr const char* kScript = R"(
import glob, os, sys
import numpy as np, torch, pyfvvdp
folder, display, fps = sys.argv[1], sys.argv[2], float(sys.argv[3])
count = len(glob.glob(os.path.join(folder, "test_*.npy")))
load = lambda kind, i: torch.from_numpy(np.load(os.path.join(folder, f"{kind}_{i:06d}.npy")))
metric = pyfvvdp.fvvdp(display_name=display, heatmap=None, device=torch.device("cpu"))
if fps > 0:
    jod, _ = metric.predict(torch.stack([load("test", i) for i in range(count)]),
                            torch.stack([load("ref", i) for i in range(count)]),
                            dim_order="FHWC", frames_per_second=fps)
    print(float(jod))
else:
    for i in range(count):
        jod, _ = metric.predict(load("test", i), load("ref", i), dim_order="HWC")
        print(float(jod))
)";

std::string shellQuoted(const std::string& text) {
  std::string out = "'";
  for (char c : text) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

std::string lastLine(const fs::path& path) {
  std::ifstream in(path);
  std::string line, last;
  while (std::getline(in, line))
    if (!line.empty()) last = line;
  return last;
}

}  // namespace

FvvdpScorer::FvvdpScorer(FvvdpSettings settings) : settings_(std::move(settings)) {
  std::string pattern = (fs::temp_directory_path() / "dnmetrics-fvvdp-XXXXXX").string();
  if (!mkdtemp(pattern.data()))
    throw std::runtime_error("--fvvdp: cannot make a temporary folder in " +
                             fs::temp_directory_path().string());
  folder_ = pattern;
}

FvvdpScorer::~FvvdpScorer() {
  std::error_code ignored;
  fs::remove_all(folder_, ignored);
}

void FvvdpScorer::add(const Image& reference, const Image& test) {
  const std::string index = fmt::format("{:06d}", pairs_++);
  npy::writeImage((folder_ / ("ref_" + index + ".npy")).string(), metrics::reinhardSrgb(reference));
  npy::writeImage((folder_ / ("test_" + index + ".npy")).string(), metrics::reinhardSrgb(test));
}

std::vector<double> FvvdpScorer::score() const {
  const fs::path script = folder_ / "score.py", out = folder_ / "out.txt",
                 err = folder_ / "err.txt";
  std::ofstream(script) << kScript;
  const std::string command = fmt::format(
      "{} {} {} {} {} >{} 2>{}", shellQuoted(settings_.python), shellQuoted(script.string()),
      shellQuoted(folder_.string()), shellQuoted(settings_.display), settings_.fps,
      shellQuoted(out.string()), shellQuoted(err.string()));
  if (std::system(command.c_str()) != 0) {
    const std::string why = lastLine(err);
    throw std::runtime_error(
        "--fvvdp: " + settings_.python +
        " could not score: " + (why.empty() ? std::string("no such interpreter?") : why) +
        (why.find("No module named") != std::string::npos ? " (pip install pyfvvdp)" : ""));
  }
  std::vector<double> scores;
  std::ifstream in(out);
  for (double v; in >> v;) scores.push_back(v);
  const std::size_t expected = settings_.fps > 0 ? 1 : std::size_t(pairs_);
  if (scores.size() != expected)
    throw std::runtime_error(fmt::format("--fvvdp: {} printed {} scores, {} expected",
                                         settings_.python, scores.size(), expected));
  return scores;
}

}  // namespace dn::cli
