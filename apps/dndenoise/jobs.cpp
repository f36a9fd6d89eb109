#include "dndenoise/jobs.h"

#include <fmt/format.h>
#include <torch/torch.h>

#include <algorithm>
#include <filesystem>

#include "common/app.h"
#include "common/cli.h"
#include "common/sequence.h"
#include "dn/io/frame_pattern.h"
#include "dn/io/preview_io.h"
#include "dn/passes/sequence_passes.h"

namespace fs = std::filesystem;

namespace dn::dndenoise {

// (input, output) pairs from files, patterns or a folder output.
Jobs planJobs(const Options& o) {
  Jobs jobs;
  if (!o.separateFiles.empty()) return {{"", o.output}};
  const bool outPattern = isFramePattern(o.output);
  for (const auto& input : o.inputs) {
    if (isFramePattern(input)) {
      if (!outPattern)
        throw cli::UsageError("a frame sequence needs an output pattern such as out.#.exr");
      for (const auto& [number, path] :
           cli::sequenceFrames(input, o.frames, o.skipMissing, "dndenoise"))
        jobs.emplace_back(path, frameFile(o.output, number));
    } else if (o.inputs.size() > 1 || fs::is_directory(o.output)) {
      if (!fs::is_directory(o.output))
        throw cli::UsageError("several inputs need -o to be an existing folder");
      jobs.emplace_back(input, (fs::path(o.output) / fs::path(input).filename()).string());
    } else {
      if (outPattern)
        throw cli::UsageError(o.output + ": an output pattern needs an input pattern");
      jobs.emplace_back(input, o.output);
    }
  }
  if (!o.frames.empty() && std::none_of(o.inputs.begin(), o.inputs.end(), isFramePattern))
    throw cli::UsageError("--frames needs an input pattern such as in.#.exr");
  return jobs;
}

// Where each job's --preview picture goes: the one file given, or in a folder
// under the output's name (out.0001.exr -> DIR/out.0001.png) for many outputs.
std::vector<std::string> planPreviews(const Options& o, const Jobs& jobs) {
  if (o.preview.empty()) return {};
  const bool folder = fs::is_directory(o.preview);
  if (!folder && outputKindFor(o.preview) != OutputKind::Display)
    throw cli::UsageError("--preview takes a PNG, JPEG or TIFF picture or a folder, not '" +
                          o.preview + "'");
  if (!folder && jobs.size() > 1)
    throw cli::UsageError("--preview: several outputs need an existing folder for their pictures");
  std::vector<std::string> previews;
  for (const auto& job : jobs) {
    const fs::path name = fs::path(job.second).filename().replace_extension(".png");
    previews.push_back(folder ? (fs::path(o.preview) / name).string() : o.preview);
    if (previews.back() == job.second)
      throw cli::UsageError("--preview " + previews.back() + " is the output itself");
  }
  return previews;
}

// The display transform, built (and its config, display and view checked)
// before the model loads, when some picture needs it.
std::optional<tonemap::OcioDisplay> displayFor(const Options& o, const Jobs& jobs) {
  bool needed = !o.preview.empty();
  for (const auto& job : jobs)
    needed |= outputKindFor(job.second, o.floatOut) == OutputKind::Display;
  if (!needed && !(o.display.config + o.display.display + o.display.view).empty())
    throw cli::UsageError(
        "--ocio, --display and --view apply to PNG, JPEG or TIFF outputs and --preview");
  if (!needed) return std::nullopt;
  std::optional<tonemap::OcioDisplay> display(std::in_place, o.display);
  if (o.verbose) fmt::print(stderr, "dndenoise: pictures through {}\n", display->description());
  return display;
}

// Every check that needs no denoising, before the first frame: files readable,
// no output over an input or over another output, output folders writable.
void checkFilesBeforeWork(const Options& o, const Jobs& jobs,
                          const std::vector<std::string>& previews) {
  std::vector<std::string> inputs = {o.model};
  std::vector<cli::Output> outputs;
  for (const auto& [buffer, file] : o.separateFiles) inputs.push_back(file);
  for (std::size_t j = 0; j < jobs.size(); ++j) {
    const auto& [input, output] = jobs[j];
    const std::string source = input.empty() ? o.separateFiles.at("color") : input;
    if (!input.empty()) inputs.push_back(input);
    outputs.push_back({output, source});
    if (!previews.empty()) outputs.push_back({previews[j], source});
  }
  if (!o.reference.empty()) inputs.push_back(o.reference);
  cli::checkFiles(inputs, outputs, o.inplace ? cli::Inplace::Allow : cli::Inplace::Offer);
}

std::unique_ptr<temporal::Sequence> planSequence(const Options& o, const Jobs& jobs,
                                                 const Denoiser& denoiser) {
  if (!o.temporal || o.inputs.size() != 1 || !isFramePattern(o.inputs.front())) return nullptr;
  temporal::SequenceSettings settings = o.sequence;
  settings.read = o.read;
  settings.filter.threads = torch::get_num_threads();
  // Each frame's passes are then denoised from its buffers as read.
  settings.framesAsRead = o.passes && o.passesOverTime == PassesOverTime::Off;
  // On CUDA the filter runs there too, the window's frames kept on the GPU.
  if (o.temporalFilter == "tensors" || (o.temporalFilter == "auto" && o.device == "cuda"))
    settings.filterDevice = torch::Device(o.device);
  const auto& notes = denoiser.info().notes;
  const auto trust = notes.find("temporal_trust");
  if (trust != notes.end() && o.temporalTrust == "learned")
    settings.filter.learnedTrust = std::make_shared<const temporal::LearnedTrust>(
        temporal::LearnedTrust::fromText(trust->second));
  settings.viewDependentShare = [](const std::string& path, const FrameBuffers& frame) {
    return viewDependentShare(path, frame);
  };
  settings.viewDependentChannels = [](const std::string& path, const std::string& layerPrefix) {
    return viewDependentChannels(path, layerPrefix);
  };
  std::vector<std::string> files;
  for (const auto& job : jobs) files.push_back(job.first);
  std::string frameByFrame;
  auto sequence = temporal::Sequence::plan(o.inputs.front(), files, settings, frameByFrame);
  if (!frameByFrame.empty()) fmt::print(stderr, "dndenoise: {}\n", frameByFrame);
  return sequence;
}

}  // namespace dn::dndenoise
