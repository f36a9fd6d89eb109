// dnmetrics: compare renders against a reference.
//   dnmetrics REF TEST...          one reference, several results
//   dnmetrics REFDIR TESTDIR       same-named files of two folders, with a summary
#include <fmt/format.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <optional>
#include <set>

#include "common/app.h"
#include "common/cli.h"
#include "common/fvvdp.h"
#include "common/progress.h"
#include "common/sequence.h"
#include "dn/flip.h"
#include "dn/io/buffer_io.h"
#include "dn/io/output_files.h"
#include "dn/metrics.h"
#include "dn/parallel.h"

namespace fs = std::filesystem;
using namespace dn;

namespace {

const char* kUsage = R"(usage: dnmetrics [options] REF TEST...
       dnmetrics [options] REFDIR TESTDIR
       dnmetrics [options] REF.#.exr TEST.#.exr   (sequences; REF may be one file for all)

Compares each TEST image with REF (or the same-named files of two folders).
Sequences get every frame's metrics and the flicker of the error, mean
|e_t - e_(t-1)| with e = R(TEST) - R(REF) per pixel and channel in the Reinhard
space R (for a frame and the one before it; on a locked-off shot with one
shared REF it is the frame-to-frame change of the result itself).
L1, MSE and SMAPE use radiance clamped to [0, 6]; relMSE linear radiance;
PSNR and SSIM Reinhard-tonemapped images; flip is LDR-FLIP of the Reinhard
images encoded as sRGB; hdrflip is HDR-FLIP of the linear images.

options:
  --metrics LIST         comma-separated subset of: l1,mse,relmse,psnr,ssim,smape,flip,hdrflip
                         (default: all)
  --format table|csv|json  output format (default: table); identical images have
                         PSNR inf: "inf" in the table and CSV, the string "inf" in
                         JSON (an undefined std is "nan" in JSON, n/a in the table)
  --heatmap FILE.png     write the FLIP error map in colour (one TEST only; never
                         one of the inputs)
  --maxerror METRIC=V    exit with code 2 if any result is worse than V >= 0
                         (repeatable; for psnr and ssim, worse means lower)
  --ref-channels LIST    channel names to read from REF, e.g. R,G,B
  --test-channels LIST   channel names to read from each TEST
                         (default: the colour of the file, or its Denoised layer if present)
  --nonfinite error|zero NaN/Inf pixels: fail (default) or count them as 0 and report
  --fvvdp                also FovVideoVDP in JOD (higher is better, 10: no visible
                         difference), through pyfvvdp in a Python subprocess,
                         on the images as FLIP sees them; a sequence is scored
                         as one video, in a row of its own
  --fvvdp-python PATH    the interpreter that has pyfvvdp (default: $DN_FVVDP_PYTHON,
                         else python3)
  --fps N                a sequence's frame rate for --fvvdp (default: 24)
  --threads N            worker threads, 1-1024 (default: all cores)
  -v                     progress file by file on stderr
  --version              versions of the tool and its libraries
  -h, --help             this text
exit codes: 0 ok, 1 bad input or arguments, 2 a --maxerror check failed
)";

struct Options {
  std::vector<std::string> inputs;
  std::vector<std::string> metrics = metrics::metricNames();
  std::string format = "table";
  std::string heatmap;
  std::vector<std::pair<std::string, double>> maxErrors;
  std::vector<std::string> refChannels, testChannels;
  bool zeroNonFinite = false;
  bool verbose = false;
  bool fvvdp = false;
  cli::FvvdpSettings fvvdpSettings;
  double fps = 24;
};

std::vector<std::string> channelList(const std::string& option, const std::string& text) {
  auto list = cli::splitList(text);
  if (list.size() != 1 && list.size() != 3)
    throw cli::UsageError(option + " needs 1 or 3 channel names, e.g. R,G,B; got '" + text + "'");
  return list;
}

Options parseArgs(int argc, char** argv) {
  cli::Args args(argc, argv);
  Options o;
  if (const char* python = std::getenv("DN_FVVDP_PYTHON"); python && *python)
    o.fvvdpSettings.python = python;
  while (!args.done()) {
    if (args.flag("-h", "--help")) {
      std::fputs(kUsage, stdout);
      std::exit(cli::kExitOk);
    } else if (args.flag("--version")) {
      std::fputs(cli::versionText("dnmetrics", cli::commonComponents()).c_str(), stdout);
      std::exit(cli::kExitOk);
    } else if (args.flag("--metrics")) {
      o.metrics = cli::splitList(args.value("--metrics"));
      if (o.metrics.empty()) throw cli::UsageError("--metrics needs a list such as l1,psnr");
      for (const auto& m : o.metrics)
        if (!metrics::isMetricName(m))
          throw cli::UsageError("--metrics: unknown metric '" + m + "'");
    } else if (args.flag("--format")) {
      o.format = args.value("--format");
      if (o.format != "table" && o.format != "csv" && o.format != "json")
        throw cli::UsageError("--format must be table, csv or json");
    } else if (args.flag("--heatmap")) {
      o.heatmap = args.value("--heatmap");
    } else if (args.flag("--maxerror")) {
      std::string spec = args.value("--maxerror");
      auto eq = spec.find('=');
      std::string name = spec.substr(0, eq);
      if (eq == std::string::npos || !metrics::isMetricName(name))
        throw cli::UsageError("--maxerror expects METRIC=VALUE with a known metric, got '" + spec +
                              "'");
      const double limit = cli::Args::toDouble("--maxerror", spec.substr(eq + 1));
      if (limit < 0) throw cli::UsageError("--maxerror must be >= 0, got '" + spec + "'");
      o.maxErrors.emplace_back(name, limit);
    } else if (args.flag("--ref-channels")) {
      o.refChannels = channelList("--ref-channels", args.value("--ref-channels"));
    } else if (args.flag("--test-channels")) {
      o.testChannels = channelList("--test-channels", args.value("--test-channels"));
    } else if (args.flag("--nonfinite")) {
      std::string v = args.value("--nonfinite");
      if (v != "error" && v != "zero") throw cli::UsageError("--nonfinite must be error or zero");
      o.zeroNonFinite = v == "zero";
    } else if (args.flag("--fvvdp")) {
      o.fvvdp = true;
    } else if (args.flag("--fvvdp-python")) {
      o.fvvdpSettings.python = args.value("--fvvdp-python");
    } else if (args.flag("--fps")) {
      o.fps = cli::Args::toDouble("--fps", args.value("--fps"));
      if (!(o.fps > 0)) throw cli::UsageError("--fps must be > 0");
    } else if (args.flag("--threads")) {
      kernelThreadCount() = args.intValue("--threads", 1, 1024);
    } else if (args.flag("-v", "--verbose")) {
      o.verbose = true;
    } else if (args.peek().size() > 1 && args.peek()[0] == '-') {
      throw cli::UsageError("unknown option '" + args.peek() + "' (see --help)");
    } else {
      o.inputs.push_back(args.positional());
    }
  }
  if (o.inputs.size() < 2)
    throw cli::UsageError("need a reference and at least one test image (see --help)");
  // Every metric named by --maxerror must be computed.
  for (const auto& [name, v] : o.maxErrors)
    if (std::find(o.metrics.begin(), o.metrics.end(), name) == o.metrics.end())
      o.metrics.push_back(name);
  if (!o.heatmap.empty() &&
      std::find(o.metrics.begin(), o.metrics.end(), "flip") == o.metrics.end() &&
      std::find(o.metrics.begin(), o.metrics.end(), "hdrflip") == o.metrics.end())
    o.metrics.push_back("flip");
  return o;
}

// A result file's denoised layer if it has one, else its colour.
Image loadColor(const std::string& path, const std::vector<std::string>& channels,
                bool preferDenoised) {
  if (!channels.empty()) return readImage(path, 0, channels);
  if (preferDenoised) {
    auto names = channelNames(path);
    for (const auto& n : names) {
      if (n.size() < 10 || n.compare(n.size() - 10, 10, "Denoised.R") != 0) continue;
      std::string prefix = n.substr(0, n.size() - 1);
      if (std::count(names.begin(), names.end(), prefix + "G") &&
          std::count(names.begin(), names.end(), prefix + "B"))
        return readImage(path, 0, {prefix + "R", prefix + "G", prefix + "B"});
    }
  }
  return readImage(path, 3);
}

Image loadChecked(const std::string& path, const std::vector<std::string>& channels,
                  bool preferDenoised, bool zeroNonFinite, std::size_t& nonFinite) {
  Image image = loadColor(path, channels, preferDenoised);
  nonFinite = countAndZeroNonFinite(image);
  if (nonFinite > 0 && !zeroNonFinite)
    throw IoError(fmt::format("{}: {} NaN/Inf values (use --nonfinite zero to count them as 0)",
                              path, nonFinite));
  if (nonFinite > 0)
    fmt::print(stderr, "dnmetrics: {}: {} NaN/Inf values counted as 0\n", path, nonFinite);
  return image;
}

struct Row {
  std::string name;
  std::map<std::string, double> values;
  bool video = false;  // a sequence's FovVideoVDP as one video: no other metric
};

bool isImageFile(const fs::path& p) {
  static const std::set<std::string> exts = {".exr", ".pfm",  ".hdr", ".png",
                                             ".tif", ".tiff", ".jpg", ".jpeg"};
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
  return fs::is_regular_file(p) && exts.count(ext);
}

// (reference, test, display name) triples for frame sequences: TEST a
// pattern, REF a pattern of the same frame numbers or one file for them all.
std::vector<std::array<std::string, 3>> pairUpSequence(const Options& o) {
  std::vector<std::array<std::string, 3>> pairs;
  const bool refPattern = isFramePattern(o.inputs[0]);
  for (const auto& [number, test] : cli::sequenceFrames(o.inputs[1], "", false, "dnmetrics"))
    pairs.push_back({refPattern ? frameFile(o.inputs[0], number) : o.inputs[0], test, test});
  return pairs;
}

bool isSequence(const Options& o) { return o.inputs.size() == 2 && isFramePattern(o.inputs[1]); }

// (reference, test, display name) triples for both modes.
std::vector<std::array<std::string, 3>> pairUp(const Options& o) {
  if (isSequence(o)) return pairUpSequence(o);
  std::vector<std::array<std::string, 3>> pairs;
  if (!fs::is_directory(o.inputs[0])) {
    for (std::size_t i = 1; i < o.inputs.size(); ++i) {
      if (fs::is_directory(o.inputs[i]))
        throw IoError(o.inputs[i] + ": is a folder but REF is a file");
      pairs.push_back({o.inputs[0], o.inputs[i], o.inputs[i]});
    }
    return pairs;
  }
  if (o.inputs.size() != 2 || !fs::is_directory(o.inputs[1]))
    throw cli::UsageError("folder mode takes exactly REFDIR TESTDIR");
  std::vector<std::string> missing;
  for (const auto& entry : fs::directory_iterator(o.inputs[0])) {
    if (!isImageFile(entry.path())) continue;
    fs::path test = fs::path(o.inputs[1]) / entry.path().filename();
    if (!fs::exists(test))
      missing.push_back(entry.path().filename().string());
    else
      pairs.push_back({entry.path().string(), test.string(), entry.path().filename().string()});
  }
  if (!missing.empty())
    throw IoError(o.inputs[1] + ": missing " + std::to_string(missing.size()) + " file(s) of " +
                  o.inputs[0] + ", e.g. " + missing.front());
  if (pairs.empty()) throw IoError(o.inputs[0] + ": no images to compare");
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}

void writeHeatmap(const std::string& path, const metrics::Comparison& c) {
  const Image& map = c.flipMap.empty() ? c.hdrFlipMap : c.flipMap;
  Image heat = flip::magmaHeatmap(map);
  writeImage(path, heat, false);
}

// Over the rows where the metric is defined (a sequence's first frame has no flicker).
std::pair<double, double> meanAndStd(const std::vector<Row>& rows, const std::string& metric) {
  double sum = 0, sq = 0;
  std::size_t n = 0;
  for (const auto& r : rows)
    if (!std::isnan(r.values.at(metric))) sum += r.values.at(metric), ++n;
  if (n == 0) return {NAN, NAN};
  double mean = sum / n;
  for (const auto& r : rows)
    if (!std::isnan(r.values.at(metric)))
      sq += (r.values.at(metric) - mean) * (r.values.at(metric) - mean);
  if (!std::isfinite(mean)) return {mean, NAN};
  return {mean, n > 1 ? std::sqrt(sq / (n - 1)) : 0.0};
}

// JSON has no infinity: identical images' PSNR is the string "inf" (and an
// undefined spread "nan"), as the table and CSV print them.
using Json = nlohmann::ordered_json;  // keys in the order written

Json jsonNumber(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  return v;
}

// RFC 4180: a field holding a comma, a quote or a line break is quoted, its
// quotes doubled.
std::string csvField(const std::string& text) {
  if (text.find_first_of(",\"\r\n") == std::string::npos) return text;
  std::string out = "\"";
  for (char c : text) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

std::string csvNumber(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  return fmt::format("{:.8g}", v);
}

// Table cells: 5 significant digits; "inf" for a perfect PSNR, "n/a" for undefined spreads.
std::string cell(double v) {
  if (std::isnan(v)) return "n/a";
  return std::isinf(v) ? "inf" : fmt::format("{:.5g}", v);
}

void print(const Options& o, const std::vector<Row>& rows) {
  const bool summary = rows.size() > 1;
  if (o.format == "json") {
    auto object = [&](const std::map<std::string, double>& values) {
      Json j = Json::object();
      for (const auto& m : o.metrics) j[m] = jsonNumber(values.at(m));
      return j;
    };
    Json out;
    out["reference"] = o.inputs[0];
    out["results"] = Json::array();
    for (const auto& r : rows) {
      Json row = {{"file", r.name}};
      row.update(object(r.values));
      out["results"].push_back(row);
    }
    std::map<std::string, double> mean, spread;
    for (const auto& m : o.metrics) std::tie(mean[m], spread[m]) = meanAndStd(rows, m);
    out["mean"] = object(mean);
    out["std"] = object(spread);
    // Invalid UTF-8 in a file name is replaced, not thrown.
    fmt::print("{}\n", out.dump(2, ' ', false, Json::error_handler_t::replace));
  } else if (o.format == "csv") {
    fmt::print("file");
    for (const auto& m : o.metrics) fmt::print(",{}", m);
    fmt::print("\n");
    for (const auto& r : rows) {
      fmt::print("{}", csvField(r.name));
      for (const auto& m : o.metrics) fmt::print(",{}", csvNumber(r.values.at(m)));
      fmt::print("\n");
    }
    if (summary) {
      fmt::print("mean");
      for (const auto& m : o.metrics) fmt::print(",{}", csvNumber(meanAndStd(rows, m).first));
      fmt::print("\n");
    }
  } else {
    std::size_t width = 4;
    for (const auto& r : rows) width = std::max(width, r.name.size());
    fmt::print("reference: {}\n{:<{}}", o.inputs[0], "file", width);
    for (const auto& m : o.metrics) fmt::print("  {:>10}", m);
    fmt::print("\n");
    for (const auto& r : rows) {
      fmt::print("{:<{}}", r.name, width);
      for (const auto& m : o.metrics) fmt::print("  {:>10}", cell(r.values.at(m)));
      fmt::print("\n");
    }
    if (summary) {
      fmt::print("{:<{}}", "mean", width);
      for (const auto& m : o.metrics) fmt::print("  {:>10}", cell(meanAndStd(rows, m).first));
      fmt::print("\n{:<{}}", "std", width);
      for (const auto& m : o.metrics) fmt::print("  {:>10}", cell(meanAndStd(rows, m).second));
      fmt::print("\n");
    }
  }
}

int run(const Options& o, int argc, char** argv) {
  auto pairs = pairUp(o);
  if (!o.heatmap.empty() && pairs.size() != 1)
    throw cli::UsageError("--heatmap needs exactly one TEST");
  std::vector<std::string> inputs;
  for (const auto& [refPath, testPath, name] : pairs)
    inputs.push_back(refPath), inputs.push_back(testPath);
  std::vector<cli::Output> outputs;
  if (!o.heatmap.empty()) outputs.push_back({o.heatmap, pairs[0][1]});
  cli::checkFiles(inputs, outputs);
  cli::setToolProvenance("dnmetrics", argc, argv);
  std::vector<Row> rows;
  std::string loadedRef;  // a shared reference is read once
  Image ref, previousRef, previousTest;
  const bool sequence = isSequence(o);
  std::optional<cli::FvvdpScorer> fvvdp;
  if (o.fvvdp) {
    cli::FvvdpSettings settings = o.fvvdpSettings;
    settings.fps = sequence ? o.fps : 0;
    fvvdp.emplace(settings);
  }
  std::optional<cli::Progress> progress;
  if (o.verbose) progress.emplace(stderr);
  for (const auto& [refPath, testPath, name] : pairs) {
    if (progress)
      progress->update(double(rows.size()) / pairs.size(),
                       fmt::format("dnmetrics: [{}/{}] {}", rows.size() + 1, pairs.size(), name));
    std::size_t nonFinite = 0;
    if (refPath != loadedRef) {
      ref = loadChecked(refPath, o.refChannels, false, o.zeroNonFinite, nonFinite);
      loadedRef = refPath;
    }
    Image test = loadChecked(testPath, o.testChannels, true, o.zeroNonFinite, nonFinite);
    if (test.width != ref.width || test.height != ref.height)
      throw IoError(fmt::format("{}: size {}x{} does not match reference {} ({}x{})", testPath,
                                test.width, test.height, refPath, ref.width, ref.height));
    auto comparison = metrics::compare(ref, test, o.metrics);
    if (fvvdp) fvvdp->add(ref, test);
    if (!o.heatmap.empty()) writeHeatmap(o.heatmap, comparison);
    if (sequence) {
      if (!previousTest.empty() && !previousTest.sameShape(test))
        throw IoError(testPath + ": not the size of the frame before it");
      comparison.values["flicker"] =
          previousTest.empty() ? NAN : metrics::flicker(previousRef, previousTest, ref, test);
      previousRef = ref, previousTest = std::move(test);
    }
    rows.push_back({name, comparison.values});
  }
  if (progress) progress->finish();
  Options shown = o;
  if (sequence) shown.metrics.push_back("flicker");
  if (fvvdp) {
    const std::vector<double> scores = fvvdp->score();
    for (std::size_t i = 0; i < rows.size(); ++i)
      rows[i].values["fvvdp"] = sequence ? NAN : scores[i];
    if (sequence) {
      Row video{fmt::format("{} (video, {:g} fps)", o.inputs[1], o.fps), {}, true};
      for (const auto& [metric, value] : rows.front().values) video.values[metric] = NAN;
      video.values["fvvdp"] = scores.front();
      rows.push_back(video);
    }
    shown.metrics.push_back("fvvdp");
  }
  print(shown, rows);

  int status = cli::kExitOk;
  for (const auto& [metric, limit] : o.maxErrors)
    for (const auto& r : rows) {
      if (r.video) continue;
      double v = r.values.at(metric);
      bool worse = metrics::higherIsBetter(metric) ? !(v >= limit) : !(v <= limit);
      if (worse) {
        fmt::print(stderr, "dnmetrics: {}: {} = {:.6g} is worse than the limit {:.6g}\n", r.name,
                   metric, v, limit);
        status = cli::kExitThreshold;
      }
    }
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  removeTemporaryFilesOnSignal("dnmetrics");
  try {
    return run(parseArgs(argc, argv), argc, argv);
  } catch (const std::exception& e) {
    fmt::print(stderr, "dnmetrics: {}\n", e.what());
  }
  return cli::kExitError;
}
