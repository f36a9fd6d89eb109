// dndenoise: denoise Monte Carlo renders with a diffusion model and the
// renderer's feature buffers.
//   dndenoise IN.exr -o OUT.exr
//   dndenoise --color c.pfm --albedo a.pfm --normal n.pfm ... -o OUT.exr
//   dndenoise shot.#.exr -o out.#.exr
// The options and their checks are in dndenoise/options.cpp, the plan of
// jobs in dndenoise/jobs.cpp, the inputs in dndenoise/inputs.cpp, what it
// prints in dndenoise/report.cpp and the outputs in dndenoise/outputs.cpp;
// the denoising, the sequences and the light passes are the library's.
#include <fmt/format.h>
#include <torch/torch.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <future>
#include <optional>

#include "common/app.h"
#include "common/cli.h"
#include "common/finite.h"
#include "common/progress.h"
#include "dn/infer/denoiser.h"
#include "dn/io/output_files.h"
#include "dn/io/preview_io.h"
#include "dn/io/sha256.h"
#include "dn/nn/reusing_allocator.h"
#include "dn/passes/joint_denoise.h"
#include "dn/passes/sequence_passes.h"
#include "dn/temporal/sequence.h"
#include "dndenoise/inputs.h"
#include "dndenoise/jobs.h"
#include "dndenoise/options.h"
#include "dndenoise/outputs.h"
#include "dndenoise/report.h"

namespace fs = std::filesystem;
using namespace dn;
using namespace dn::dndenoise;
using Clock = std::chrono::steady_clock;

namespace {

Denoiser loadModel(const Options& o) {
  try {
    return Denoiser::fromFile(o.model);
  } catch (const ModelError& e) {
    throw IoError(e.what());
  }
}

int run(Options o, int argc, char** argv) {
  const Jobs jobs = planJobs(o);
  const std::vector<std::string> previews = planPreviews(o, jobs);
  const std::optional<tonemap::OcioDisplay> display = displayFor(o, jobs);
  checkFilesBeforeWork(o, jobs, previews);
  // Freed activations are reused, not handed back to the kernel to be zeroed
  // again, within the peak the networks reach anyway (dn/nn/reusing_allocator.h).
  useReusingCpuAllocator(static_cast<std::size_t>(o.denoise.maxMemoryBytes));
  useReusingAllocatorForNew();
  const auto loadStart = Clock::now();
  // The checksum for the outputs' metadata, on the core the loading leaves idle.
  auto modelSha256 = std::async(std::launch::async, [&] { return sha256OfFile(o.model); });
  const Denoiser denoiser = loadModel(o);
  checkOptionsApply(o, denoiser);
  if (o.verbose)
    fmt::print(stderr, "dndenoise: model {} loaded in {:.2f} s\n", o.model,
               std::chrono::duration<double>(Clock::now() - loadStart).count());
  cli::setToolProvenance("dndenoise", argc, argv, o.model, modelSha256.get());
  const Image ref = o.reference.empty() ? Image() : readReference(o);
  // Every input's header before the first frame: a bad frame 90 fails now, not in an hour.
  for (const auto& [input, output] : jobs) {
    if (!input.empty()) readInputHeader(o, denoiser, input);
    if (o.passes && outputKindFor(output, o.floatOut) != OutputKind::Layered)
      throw cli::UsageError("--passes writes a multilayer EXR, not " + output);
    if (o.passes) requireLightPasses(input, o.read.viewLayer);
  }
  // The passes run the networks the denoiser already loaded.
  const OidnBase passBase = o.passes ? denoiser.oidnBase() : OidnBase(nullptr);
  if (o.passes) requirePrefilterNetworks(passBase, o.model);
  const auto sequence = planSequence(o, jobs, denoiser);
  // On a sequence the light passes are filtered with the beauty's weights.
  const bool passesOverTime = sequence && o.passes && o.passesOverTime != PassesOverTime::Off;
  const temporal::Sequence::Read readFile = [&](const std::string& path,
                                                const ChannelGroups& extra) {
    return readInput(o, denoiser, path, path, extra);
  };

  int status = cli::kExitOk;
  std::optional<cli::Progress> progress;
  if (o.verbose) progress.emplace(stderr);
  for (std::size_t j = 0; j < jobs.size(); ++j) {
    const auto& [input, output] = jobs[j];
    const std::string name = input.empty() ? o.separateFiles.at("color") : input;
    // A sequence's frame is read once, into the window (as a neighbour, or
    // as it is denoised), and put back together here only to be looked at.
    const bool lookedAt = o.verbose || !ref.empty();
    FrameBuffers frame = !sequence  ? readInput(o, denoiser, input, name)
                         : lookedAt ? sequence->frame(input, readFile)
                                    : FrameBuffers();
    if (!ref.empty()) checkReferenceSize(o, ref, frame, name);
    if (o.verbose) {
      for (const auto& note : frame.notes) fmt::print(stderr, "dndenoise: {}: {}\n", name, note);
      reportInputStatistics(name, frame.get("color"));
    }
    // The window holds the frame while the networks run; it is put back
    // together once denoised.
    if (sequence) frame = FrameBuffers();

    DenoiseOptions options = o.denoise;
    options.device = torch::Device(o.device);
    options.returnCleanAux = sequence != nullptr;  // its accumulated renders are denoised on them
    const auto start = Clock::now();
    if (progress)
      options.progress = [&, j](double f) {
        double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
        progress->update((j + f) / jobs.size(),
                         fmt::format("dndenoise: {} [{}/{}] {:3.0f}%  elapsed {}  ETA {}",
                                     fs::path(name).filename().string(), j + 1, jobs.size(),
                                     100 * f, cli::formatDuration(elapsed),
                                     cli::formatDuration(f > 0 ? elapsed * (1 - f) / f : 0)));
      };
    SequencePassOptions passOptions{passOptionsFor(options), o.passesOverTime};
    DenoiseOptions again = options;  // the accumulated renders' second denoising
    if (passesOverTime)
      again.precision = passOptions.accumulatedPrecision =
          secondDenoisingPrecision(options.precision, options.device, o.wasGiven("--precision"));
    const auto alone = [&](const std::string&, const FrameBuffers& f) {
      return denoiser.denoise(f, f.accumulated ? again : options);
    };
    std::vector<double> times;
    DenoiseResult result;
    std::map<std::string, Image> filteredPasses;
    for (int r = 0; r < o.repeats; ++r) {
      const auto t0 = Clock::now();
      try {
        if (passesOverTime) {
          auto both =
              sequence->denoise(input, readFile, alone, lightPassCompanions(passBase, passOptions));
          result = std::move(both.result);
          filteredPasses = std::move(both.companions);
        } else {
          result = sequence ? sequence->denoise(input, readFile, alone)
                            : denoiser.denoise(frame, options);
        }
      } catch (const std::invalid_argument& e) {
        throw IoError(fmt::format("{}: {}", name, e.what()));
      }
      times.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
    }
    if (progress) progress->finish();
    if (sequence) frame = sequence->frame(input, readFile);
    if (o.verbose && sequence) fmt::print(stderr, "dndenoise: {}: {}\n", name, sequence->report());
    if (sequence && !sequence->aloneBecause().empty())
      fmt::print(stderr, "dndenoise: {}: {}\n", name, sequence->aloneBecause());
    reportResult(o, denoiser, name, input, frame, result, std::move(times));

    // Nothing non-finite leaves the tool: overflow becomes the largest float.
    const std::size_t clamped =
        cli::clampToFinite(result.color) + cli::clampToFinite(result.uncertainty);
    if (clamped > 0)
      fmt::print(stderr, "dndenoise: {}: {} values beyond the float range clamped\n", name,
                 clamped);
    std::optional<PassesResult> passes;
    if (o.passes) {
      passes = passesOverTime
                   ? passesOfSequenceFrame(input, frame, filteredPasses, result.color, passOptions)
                   : denoisePassesOfFile(passBase, input, frame, result.color, passOptions.denoise);
      if (o.verbose) reportPasses(name, *passes, passesOverTime ? &passOptions : nullptr);
    }
    writeOutputs(o, {output, previews.empty() ? "" : previews[j], input, name}, frame, result,
                 passes, display);
    if (!ref.empty()) checkAgainstReference(o, ref, result.color, status);
  }
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  removeTemporaryFilesOnSignal("dndenoise");
  int status = cli::kExitError;
  try {
    status = run(parseArgs(argc, argv), argc, argv);
  } catch (const std::exception& e) {
    fmt::print(stderr, "dndenoise: {}\n", e.what());
  }
  // Every output is closed and in place: the process ends without taking
  // LibTorch's and OpenImageIO's state apart one object at a time (0.1 s).
  std::fflush(nullptr);
  std::_Exit(status);
}
