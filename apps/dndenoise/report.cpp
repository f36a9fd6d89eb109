#include "dndenoise/report.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "common/cli.h"
#include "dn/infer/noise_estimate.h"
#include "dn/metrics.h"
#include "dndenoise/inputs.h"

namespace dn::dndenoise {

// Which of the frame's buffers the network saw, and which it had no use for.
namespace {

void reportBuffers(const std::string& name, const std::vector<std::string>& used,
                   const std::vector<std::string>& present) {
  std::string usedList, ignored;
  for (const auto& b : used) usedList += (usedList.empty() ? "" : ", ") + b;
  for (const auto& b : present)
    if (std::find(used.begin(), used.end(), b) == used.end())
      ignored += (ignored.empty() ? "" : ", ") + b;
  fmt::print(stderr, "dndenoise: {}: used {}; ignored {}\n", name, usedList,
             ignored.empty() ? "none" : ignored);
}

// The precision of the networks' inner convolutions, where not float.
const char* precisionNote(Precision precision) {
  return precision == Precision::BFloat16  ? ", bfloat16"
         : precision == Precision::Float16 ? ", half"
                                           : "";
}

}  // namespace

void reportInputStatistics(const std::string& name, const Image& color) {
  std::size_t nonFinite = 0, negative = 0;
  for (float v : color.pixels) nonFinite += !std::isfinite(v), negative += v < 0.0f;
  fmt::print(stderr, "dndenoise: {}: {}x{}, {} NaN/Inf and {} negative values (treated as 0)\n",
             name, color.width, color.height, nonFinite, negative);
}

void reportResult(const Options& o, const Denoiser& denoiser, const std::string& name,
                  const std::string& input, const FrameBuffers& frame, const DenoiseResult& result,
                  std::vector<double> times) {
  if (o.verbose)
    reportBuffers(name, result.buffersUsed,
                  input.empty() ? frame.names() : allowed(o, availableBuffers(input, o.read)));
  if (o.verbose && result.noiseLeft)
    fmt::print(stderr, "dndenoise: {}: the base left {:.0f}% of the noise: {}\n", name,
               100 * result.noiseLeft->fraction(),
               correlatedNoiseLeft(*result.noiseLeft) ? "correlated (a splatting pixel filter)"
                                                      : "independent per pixel");
  if ((o.verbose || o.repeats > 1) && !result.plan) {
    std::sort(times.begin(), times.end());
    fmt::print(stderr,
               "dndenoise: {}: {}{}, exposure x{:.3g}, {} network steps, {} tile(s) of {} px, "
               "{:.2f} s (median of {}), {:.2f} s/MPix\n",
               name,
               result.steered
                   ? fmt::format("pretrained base + Control Module, {}{}",
                                 denoiser.info().oidn.control.diffusion ? "diffusion refinement"
                                                                        : "one pass",
                                 result.prefiltered ? ", albedo and normal prefiltered" : "")
               : result.lightPathsSplit
                   ? "pretrained base, albedo and normal prefiltered, diffuse part apart"
               : result.prefiltered ? "pretrained base, albedo and normal prefiltered"
                                    : "pretrained base",
               precisionNote(o.denoise.precision), result.exposure, result.steps, result.tileCount,
               result.tileSize, times[times.size() / 2], times.size(),
               times[times.size() / 2] / (frame.width * double(frame.height) / 1e6));
  } else if (o.verbose || o.repeats > 1) {
    std::sort(times.begin(), times.end());
    fmt::print(
        stderr,
        "dndenoise: {}: {} spp, exposure x{:.3g}, {}, skip {}, {} steps, mean matching {:.2g} "
        "px, {} tile(s) of {} px, {:.2f} s (median of {}), {:.2f} s/MPix\n",
        name, result.plan->spp > 0 ? std::to_string(result.plan->spp) : "unknown", result.exposure,
        result.plan->noise >= 0 ? fmt::format("noise {:.3g} (x{:.2f} the model's)",
                                              result.plan->noise, result.plan->noiseScale)
                                : std::string("noise not measured"),
        result.plan->skip, result.steps, result.plan->meanMatchSigma, result.tileCount,
        result.tileSize, times[times.size() / 2], times.size(),
        times[times.size() / 2] / (frame.width * double(frame.height) / 1e6));
  }
}

void reportPasses(const std::string& name, const PassesResult& passes,
                  const SequencePassOptions* overTime) {
  std::string found;
  for (const auto& key : passes.layout.usedKeys())
    found += (found.empty() ? "" : ", ") + passes.layout.layerName(key);
  fmt::print(stderr, "dndenoise: {}: {} light passes {}; rule {}\n", name,
             passes.layout.rule->renderer, found, passes.layout.formula());
  for (const auto& note : passes.layout.notes)
    fmt::print(stderr, "dndenoise: {}: {}\n", name, note);
  fmt::print(stderr,
             "dndenoise: {}: denoised passes recombine to the beauty within {:.2g} relative\n",
             name, passes.denoised.maxRelativeError);
  if (!overTime) return;
  fmt::print(stderr, "dndenoise: {}: {} filtered over time with the beauty's weights\n", name,
             overTime->overTime == PassesOverTime::All
                 ? "light and colour passes"
                 : "light passes and the diffuse colour passes");
  if (overTime->accumulatedPrecision != overTime->denoise.precision)
    fmt::print(stderr,
               "dndenoise: {}: the accumulated renders, the beauty's and the passes', denoised "
               "again in {} (this CPU computes it natively; --precision {} keeps {} throughout)\n",
               name, precisionName(overTime->accumulatedPrecision),
               precisionName(overTime->denoise.precision),
               precisionName(overTime->denoise.precision));
}

void checkAgainstReference(const Options& o, const Image& ref, const Image& result, int& status) {
  auto values = metrics::compare(ref, result, {o.maxErrorMetric}).values;
  double v = values.at(o.maxErrorMetric);
  bool worse = metrics::higherIsBetter(o.maxErrorMetric) ? !(v >= o.maxError) : !(v <= o.maxError);
  fmt::print(stderr, "dndenoise: {} against {}: {:.6g} (limit {:.6g}){}\n", o.maxErrorMetric,
             o.reference, v, o.maxError, worse ? " FAILED" : "");
  if (worse) status = cli::kExitThreshold;
}

}  // namespace dn::dndenoise
