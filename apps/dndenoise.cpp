// dndenoise: denoise Monte Carlo renders with a diffusion model and the
// renderer's feature buffers.
//   dndenoise IN.exr -o OUT.exr
//   dndenoise --color c.pfm --albedo a.pfm --normal n.pfm ... -o OUT.exr
//   dndenoise shot.#.exr -o out.#.exr
#include <fmt/format.h>
#include <torch/torch.h>
#include <torch/version.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <future>
#include <map>
#include <optional>
#include <sstream>
#include <thread>

#include "common/app.h"
#include "common/cli.h"
#include "common/finite.h"
#include "common/progress.h"
#include "common/sequence.h"
#include "common/temporal_sequence.h"
#include "dn/diffusion/refine.h"
#include "dn/infer/denoiser.h"
#include "dn/io/buffer_io.h"
#include "dn/io/output_files.h"
#include "dn/io/preview_io.h"
#include "dn/io/sha256.h"
#include "dn/metrics.h"
#include "dn/nn/reusing_allocator.h"
#include "dn/parallel.h"
#include "dn/passes/joint_denoise.h"

namespace fs = std::filesystem;
using namespace dn;
using Clock = std::chrono::steady_clock;

namespace {

const char* kUsage = R"(usage: dndenoise [options] IN.exr -o OUT.exr
       dndenoise [options] --color FILE [--albedo FILE --normal FILE ...] -o OUT
       dndenoise [options] IN.#.exr -o OUT.#.exr            (frame sequences, as oiiotool)
       dndenoise [options] A.exr B.exr ... -o DIR/           (many files, model loaded once)

Denoises Monte Carlo renders with Intel Open Image Denoise's networks run in
their prefilter mode (albedo and normal denoised first, then the colour), at
about the time OIDN takes in that mode. Where the networks leave correlated
noise (a pixel filter that splats samples), the Control Module, fed the
buffers OIDN ignores, steers them with diffusion refinement. -q high adds the
light-path split. On a frame sequence with motion vectors, each frame's
result is averaged with its neighbours' where they agree (--temporal).
Multilayer EXRs from Blender/Cycles and other renderers' usual channel names
are read as they are; the result is added as a layer beside every input layer
and the input's metadata (or written alone with --rgb-only).

quality (the default model, models/default.dnm, and others over OIDN's networks):
  -q, --quality fast|balanced|high
                      fast: one network on the noisy buffers (OIDN's usual call);
                      balanced (default): albedo and normal prefiltered (OIDN's
                      prefilter mode); high: balanced plus the light-path split
                      where Cycles wrote the diffuse passes (2.1x the time,
                      0.04-0.18 dB better)
  --prefilter on|off  albedo and normal denoised first (on, default: fast turns it off)
  --light-paths on|off  the light-path split where the passes exist (off, default;
                      -q high turns it on)
  --precision float|bf16  the convolutions inside the networks in float (default:
                      OIDN's result) or bfloat16: faster on CPUs with AMX, 0.03 dB
                      lower on average (docs/dndenoise.md, Speed and memory)
  --control auto|on|off  models with a Control Module (the default): steer the base
                      when it leaves correlated noise (auto, default), always, or never
  --sigmas LIST|none  models with a diffusion Control Module (the default): the
                      refinement's noise levels, noisiest first (default: the
                      model's); none: the base's estimate alone
  --samples K         diffusion models: mean of K samples (1-256), plus their standard
                      deviation as an 'uncertainty' layer
  --seed N            random seed >= 0 (default 0): same seed, same output
  --exposure auto|K   scale the radiance by K before the networks and back after;
                      auto (default): the model's autoexposure. K must lie within
                      0.01 to 100 times the autoexposure (else exit 1)
  --model FILE        model file (default: $DN_MODEL, else default.dnm in $DN_MODEL_DIR,
                      else the shipped models/default.dnm beside the executable)
input buffers:
  --color FILE, --albedo FILE, --normal FILE, --depth FILE, --<buffer> FILE
                      one file per buffer (EXR, PFM, HDR); --alb/--nrm also work
  --channels BUF=C1,C2,C3  take a buffer from these channels (repeatable)
  --view-layer NAME   which view layer of a multilayer file (default: the only one;
                      a file with several needs it)
  --buffers LIST      use only these buffers (e.g. color,albedo), to compare buffer
                      sets (default: every buffer the model knows that the input has)
output:
  -o, --output PATH   output file, pattern or folder (required; never an input). EXR
                      keeps every layer; PNG, JPEG and TIFF get the denoised colour
                      through an OpenColorIO display/view transform (see display, below)
  --preview PATH      also write that display picture beside the EXR: a file, or
                      a folder for sequences and many files (DIR/<output name>.png)
  --frames RANGE      frames of a sequence, e.g. 1-100 or 1-100x2 (default: the
                      pattern's range, else the files found); a missing frame stops
                      the run with a line for each
  --skip-missing      denoise the frames that exist, after naming the missing ones
  --temporal on|off   sequences with motion vectors (Blender's Vector pass, motion
                      blur off; Arnold/Karma motionvector, V-Ray VRayVelocity,
                      RenderMan motionBack/Fore): on (the default) averages each
                      frame's result with its neighbours' where the motion, the
                      features and the light agree; off: every frame alone
  --window N          neighbours on each side for --temporal, 1-8 (default 4)
  --motion PATTERN    motion vectors from separate files (e.g. mv.#.exr: Blender's
                      4 channels, or 2 channels of forward motion in pixels)
  --layer NAME        result layer name (default: Denoised, in the input's view layer)
  --rgb-only          write a plain RGB image, no other layers
  --float             float result channels (default: half); with a .tif output,
                      a linear float TIFF instead of a display picture
  --inplace           allow the output to replace the input file
  --passes            also write the light passes (Cycles: Diffuse Direct ...
                      Environment; Arnold's LPE AOVs) denoised, as layers
                      "Denoised <pass>" beside them, that recombine by the
                      renderer's rule to the denoised beauty; passes the file
                      lacks are covered by a "Denoised Residual" layer. Result
                      layers are then float (docs/dndenoise.md#light-passes)
display (PNG/JPEG/TIFF outputs and --preview):
  --ocio CONFIG       OpenColorIO config file (default: $OCIO, else the built-in
                      sRGB config: clamp to [0, 1] and the sRGB curve)
  --display NAME      display (default: the config's first, e.g. sRGB)
  --view NAME         view (default: the display's first, e.g. Standard; Blender's
                      config also offers Filmic)
  --list-views        print the config's display / view pairs and exit
resources:
  --tile N            network tile size in pixels, 16-8192 (default: the whole
                      frame, or the largest tile under --maxmem)
  --maxmem MB         memory budget for network activations, >= 100 (default 3000)
  --threads N         CPU threads, 1-1024 (default: all cores)
  --device cpu|cuda   (default cpu; cuda needs a CUDA build of LibTorch and a GPU)
checks and timing:
  --ref REF --maxerror [METRIC=]V   exit 2 if the result is worse than V against REF
                      (METRIC: l1 (default), mse, relmse, psnr, ssim, smape, flip)
  -n N                denoise N times (1-1000) and report the times
  -v                  progress with ETA and input statistics on stderr
  --version           versions of the tool and its libraries
  -h, --help          this text
the from-scratch diffusion model (an experiment: --model models/diffusion-scratch.dnm,
docs/model-card-diffusion-scratch.md); with another model these exit 1:
  --steps N           diffusion steps of the respaced schedule, 1-1000 (default 27)
  --skip S            skip the S noisiest steps (0 <= S < steps) (default: the
                      model's tuned value, adapted to the noise measured on the render)
  --spp N             the input's samples per pixel, >= 1 (default: the file's Cycles
                      metadata); given, it scales the default skip and --mean-match
  --sampler ddpm|ddim sampler (default ddpm); --eta E (0-1) for DDIM
  --mean-match SIGMA  rescale the result so its local mean (Gaussian, SIGMA px)
                      matches the render's (default 2 at the model's tuning noise
                      level, scaled with the render's; 0 = off; at most 1000)
  --overlap N         tile overlap, 0-1024 and below the tile (default 32)
exit codes: 0 ok, 1 bad input or arguments, 2 a --maxerror check failed
)";

// Which models an option acts on (checked once the model is loaded).
enum class OptionScope {
  OidnBase,          // models over OIDN's networks (the default)
  Control,           // those with a Control Module
  DiffusionControl,  // those with a diffusion Control Module
  Diffusion,         // a diffusion Control Module or the from-scratch model
  Scratch,           // the from-scratch diffusion model (an experiment)
};

struct GivenOption {
  std::string flag;
  OptionScope scope;
};

struct Options {
  std::vector<std::string> inputs;
  std::map<std::string, std::string> separateFiles;  // buffer -> file
  ReadOptions read;
  std::vector<std::string> buffers;  // --buffers: the only buffers to use
  std::string output, model, layer = "Denoised", reference, maxErrorMetric = "l1", device = "cpu";
  std::string frames;
  double maxError = -1.0;
  bool rgbOnly = false, floatOut = false, inplace = false, verbose = false, skipMissing = false;
  int repeats = 1;
  DenoiseOptions denoise;
  std::string preview;
  tonemap::PreviewOptions display;
  bool listViews = false;
  bool passes = false;             // --passes
  std::vector<GivenOption> given;  // options that act on some models only
  cli::TemporalSettings temporal;
};

// The network's size multiple: a smaller tile cannot be denoised.
constexpr int kMinTile = 16;

// Ranges that need two options at once.
void checkOptionPairs(const Options& o) {
  const ScratchSampling& scratch = o.denoise.scratch;
  if (o.denoise.tile > 0 && o.denoise.overlap >= o.denoise.tile)
    throw cli::UsageError(fmt::format("--overlap {} must be smaller than --tile {}",
                                      o.denoise.overlap, o.denoise.tile));
  if (!scratch.respacing.empty() && scratch.skip >= std::stoi(scratch.respacing))
    throw cli::UsageError(
        fmt::format("--skip {} must be smaller than --steps {}", scratch.skip, scratch.respacing));
}

std::vector<std::string> splitBufferList(const std::string& text) {
  std::vector<std::string> names;
  std::stringstream stream(text);
  for (std::string name; std::getline(stream, name, ',');) {
    if (!findBufferSpec(name))
      throw cli::UsageError("--buffers: unknown buffer '" + name + "' (see docs/dndenoise.md)");
    names.push_back(name);
  }
  if (std::find(names.begin(), names.end(), "color") == names.end())
    throw cli::UsageError("--buffers must include color");
  return names;
}

Options parseArgs(int argc, char** argv) {
  cli::Args args(argc, argv);
  Options o;
  torch::set_num_threads(
      static_cast<int>(std::thread::hardware_concurrency()));  // LibTorch starts with 1
  while (!args.done()) {
    std::string a = args.peek();
    if (args.flag("-h", "--help")) {
      std::fputs(kUsage, stdout);
      std::exit(cli::kExitOk);
    } else if (args.flag("--version")) {
      auto components = cli::commonComponents();
      components.emplace_back("LibTorch", TORCH_VERSION);
      std::fputs(cli::versionText("dndenoise", components).c_str(), stdout);
      std::exit(cli::kExitOk);
    } else if (args.flag("-o", "--output")) {
      o.output = args.value("-o");
    } else if (args.flag("--model")) {
      o.model = args.value("--model");
    } else if (args.flag("-q", "--quality")) {
      const std::string v = args.value("--quality");
      const auto quality = qualityFromName(v);
      if (!quality) throw cli::UsageError("--quality must be fast, balanced or high, got " + v);
      setQuality(o.denoise, *quality);
      o.given.push_back({"--quality", OptionScope::OidnBase});
    } else if (args.flag("--precision")) {
      const std::string v = args.value("--precision");
      if (v != "float" && v != "bf16")
        throw cli::UsageError("--precision must be float or bf16, got " + v);
      o.denoise.bfloat16 = v == "bf16";
      o.given.push_back({"--precision", OptionScope::OidnBase});
    } else if (args.flag("--steps")) {
      o.denoise.scratch.respacing = std::to_string(args.intValue("--steps", 1, 1000));
      o.given.push_back({"--steps", OptionScope::Scratch});
    } else if (args.flag("--skip")) {
      o.denoise.scratch.skip = args.intValue("--skip", 0, 999);
      o.given.push_back({"--skip", OptionScope::Scratch});
    } else if (args.flag("--sampler")) {
      std::string s = args.value("--sampler");
      if (s != "ddpm" && s != "ddim") throw cli::UsageError("--sampler must be ddpm or ddim");
      o.denoise.scratch.sampler = s == "ddim" ? SamplerKind::Ddim : SamplerKind::Ddpm;
      o.given.push_back({"--sampler", OptionScope::Scratch});
    } else if (args.flag("--eta")) {
      o.denoise.scratch.eta = args.doubleValue("--eta", 0.0, 1.0);
      o.given.push_back({"--eta", OptionScope::Scratch});
    } else if (args.flag("--spp")) {
      o.denoise.scratch.spp = args.intValue("--spp", 1, 1 << 24);
      o.given.push_back({"--spp", OptionScope::Scratch});
    } else if (args.flag("--exposure")) {
      const std::string v = args.value("--exposure");
      o.denoise.exposure = v == "auto" ? 0.0 : cli::Args::toDouble("--exposure", v);
      if (v != "auto" && !(o.denoise.exposure > 0.0 && o.denoise.exposure <= 1e6))
        throw cli::UsageError("--exposure must be auto or a number in (0, 1e6], got " + v);
    } else if (args.flag("--sigmas")) {
      const std::string spec = args.value("--sigmas");
      std::vector<double> sigmas;
      if (spec != "none")
        for (const auto& item : cli::splitList(spec))
          sigmas.push_back(cli::Args::toDouble("--sigmas", item));
      try {
        checkSigmas(sigmas);
      } catch (const std::invalid_argument& e) {
        throw cli::UsageError(std::string("--sigmas: ") + e.what());
      }
      o.denoise.sigmas = sigmas;
      o.given.push_back({"--sigmas", OptionScope::DiffusionControl});
    } else if (args.flag("--control")) {
      const std::string v = args.value("--control");
      if (v == "auto")
        o.denoise.control = ControlUse::Auto;
      else if (v == "on")
        o.denoise.control = ControlUse::Always;
      else if (v == "off")
        o.denoise.control = ControlUse::Never;
      else
        throw cli::UsageError("--control must be auto, on or off, got " + v);
      o.given.push_back({"--control", OptionScope::Control});
    } else if (args.flag("--prefilter")) {
      const std::string v = args.value("--prefilter");
      if (v != "on" && v != "off") throw cli::UsageError("--prefilter must be on or off, got " + v);
      o.denoise.prefilter = v == "on";
      o.given.push_back({"--prefilter", OptionScope::OidnBase});
    } else if (args.flag("--light-paths")) {
      const std::string v = args.value("--light-paths");
      if (v != "on" && v != "off")
        throw cli::UsageError("--light-paths must be on or off, got " + v);
      o.denoise.lightPaths = v == "on";
      o.given.push_back({"--light-paths", OptionScope::OidnBase});
    } else if (args.flag("--seed")) {
      o.denoise.seed = static_cast<uint64_t>(args.intValue("--seed", 0, INT32_MAX));
    } else if (args.flag("--samples")) {
      o.denoise.samples = args.intValue("--samples", 1, 256);
      o.given.push_back({"--samples", OptionScope::Diffusion});
    } else if (args.flag("--mean-match")) {
      o.denoise.scratch.meanMatchSigma = args.doubleValue("--mean-match", 0.0, 1000.0);
      o.given.push_back({"--mean-match", OptionScope::Scratch});
    } else if (args.flag("--channels")) {
      try {
        o.read.overrides.insert(parseChannelOverride(args.value("--channels")));
      } catch (const std::invalid_argument& e) {
        throw cli::UsageError(std::string("--channels: ") + e.what());
      }
    } else if (args.flag("--buffers")) {
      o.buffers = splitBufferList(args.value("--buffers"));
    } else if (args.flag("--view-layer")) {
      o.read.viewLayer = args.value("--view-layer");
    } else if (args.flag("--layer")) {
      o.layer = args.value("--layer");
      if (o.layer.empty() || o.layer.find_first_of(". \t\n") != std::string::npos)
        throw cli::UsageError("--layer needs a name without dots or spaces, got '" + o.layer + "'");
    } else if (args.flag("--frames")) {
      o.frames = args.value("--frames");
      cli::parseFrameRange(o.frames);
    } else if (args.flag("--skip-missing")) {
      o.skipMissing = true;
    } else if (args.flag("--temporal")) {
      const std::string v = args.value("--temporal");
      if (v != "on" && v != "off") throw cli::UsageError("--temporal must be on or off, got " + v);
      o.temporal.enabled = v == "on";
    } else if (args.flag("--window")) {
      o.temporal.radius = args.intValue("--window", 1, 8);
    } else if (args.flag("--motion")) {
      o.temporal.motion = args.value("--motion");
    } else if (args.flag("--rgb-only")) {
      o.rgbOnly = true;
    } else if (args.flag("--float")) {
      o.floatOut = true;
    } else if (args.flag("--inplace")) {
      o.inplace = true;
    } else if (args.flag("--passes")) {
      o.passes = true;
      o.given.push_back({"--passes", OptionScope::OidnBase});
    } else if (args.flag("--preview")) {
      o.preview = args.value("--preview");
    } else if (args.flag("--ocio")) {
      o.display.config = args.value("--ocio");
    } else if (args.flag("--display")) {
      o.display.display = args.value("--display");
    } else if (args.flag("--view")) {
      o.display.view = args.value("--view");
    } else if (args.flag("--list-views")) {
      o.listViews = true;
    } else if (args.flag("--tile")) {
      o.denoise.tile = args.intValue("--tile", kMinTile, 8192);
    } else if (args.flag("--overlap")) {
      o.denoise.overlap = args.intValue("--overlap", 0, 1024);
      o.given.push_back({"--overlap", OptionScope::Scratch});
    } else if (args.flag("--maxmem")) {
      o.denoise.maxMemoryBytes = args.doubleValue("--maxmem", 100.0, 1e7) * 1e6;
    } else if (args.flag("--threads")) {
      int n = args.intValue("--threads", 1, 1024);
      torch::set_num_threads(n);
      kernelThreadCount() = n;
    } else if (args.flag("--device")) {
      o.device = args.value("--device");
    } else if (args.flag("--ref", "-r")) {
      o.reference = args.value("--ref");
    } else if (args.flag("--maxerror")) {
      std::string v = args.value("--maxerror");
      auto eq = v.find('=');
      if (eq != std::string::npos) o.maxErrorMetric = v.substr(0, eq), v = v.substr(eq + 1);
      if (!metrics::isMetricName(o.maxErrorMetric))
        throw cli::UsageError("--maxerror: unknown metric '" + o.maxErrorMetric + "'");
      o.maxError = cli::Args::toDouble("--maxerror", v);
      if (o.maxError < 0) throw cli::UsageError("--maxerror must be >= 0, got " + v);
    } else if (args.flag("-n")) {
      o.repeats = args.intValue("-n", 1, 1000);
    } else if (args.flag("-v", "--verbose")) {
      o.verbose = true;
    } else if (a.size() > 2 && a[0] == '-' && a[1] == '-') {
      std::string name = a.substr(2);
      if (name == "alb") name = "albedo";
      if (name == "nrm") name = "normal";
      if (name == "hdr") name = "color";
      if (!findBufferSpec(name)) throw cli::UsageError("unknown option '" + a + "' (see --help)");
      args.flag(a);
      o.separateFiles[name] = args.value(a);
    } else if (a.size() > 1 && a[0] == '-') {
      throw cli::UsageError("unknown option '" + a + "' (see --help)");
    } else {
      o.inputs.push_back(args.positional());
    }
  }
  if (o.listViews) {
    std::fputs(tonemap::ocioDescribeConfig(o.display).c_str(), stdout);
    std::exit(cli::kExitOk);
  }
  if (o.output.empty()) throw cli::UsageError("no output given: use -o OUT (see --help)");
  if (o.inputs.empty() == o.separateFiles.empty())
    throw cli::UsageError(o.inputs.empty()
                              ? "no input given (see --help)"
                              : "give either IN files or --color/--albedo/... files, not both");
  if (!o.separateFiles.empty() && !o.separateFiles.count("color"))
    throw cli::UsageError("separate buffer files need --color FILE");
  if (o.maxError >= 0 && o.reference.empty()) throw cli::UsageError("--maxerror needs --ref REF");
  if (!o.reference.empty() && o.maxError < 0) throw cli::UsageError("--ref needs --maxerror");
  checkOptionPairs(o);
  if (o.passes && (o.rgbOnly || !o.separateFiles.empty()))
    throw cli::UsageError(
        "--passes needs a multilayer EXR input and output, not --rgb-only or "
        "separate buffer files");
  if (o.device != "cpu" && o.device != "cuda")
    throw cli::UsageError("--device must be cpu or cuda");
  if (o.device == "cuda" && !torch::cuda::is_available())
    throw cli::UsageError("--device cuda: no CUDA device is available to this LibTorch build");
  if (o.model.empty()) o.model = cli::defaultModelPath();
  return o;
}

// (input, output) pairs from files, patterns or a folder output.
std::vector<std::pair<std::string, std::string>> planJobs(const Options& o) {
  std::vector<std::pair<std::string, std::string>> jobs;
  if (!o.separateFiles.empty()) return {{"", o.output}};
  const bool outPattern = cli::isFramePattern(o.output);
  for (const auto& input : o.inputs) {
    if (cli::isFramePattern(input)) {
      if (!outPattern)
        throw cli::UsageError("a frame sequence needs an output pattern such as out.#.exr");
      for (const auto& [number, path] :
           cli::sequenceFrames(input, o.frames, o.skipMissing, "dndenoise"))
        jobs.emplace_back(path, cli::frameFile(o.output, number));
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
  if (!o.frames.empty() && std::none_of(o.inputs.begin(), o.inputs.end(), cli::isFramePattern))
    throw cli::UsageError("--frames needs an input pattern such as in.#.exr");
  return jobs;
}

// Where each job's --preview picture goes: the one file given, or in a folder
// under the output's name (out.0001.exr -> DIR/out.0001.png) for many outputs.
std::vector<std::string> planPreviews(
    const Options& o, const std::vector<std::pair<std::string, std::string>>& jobs) {
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
std::optional<tonemap::OcioDisplay> displayFor(
    const Options& o, const std::vector<std::pair<std::string, std::string>>& jobs) {
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
void checkFilesBeforeWork(const Options& o,
                          const std::vector<std::pair<std::string, std::string>>& jobs,
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

// Counts what the model will not see as radiance: NaN/Inf and negative values.
void reportInputStatistics(const std::string& name, const Image& color) {
  std::size_t nonFinite = 0, negative = 0;
  for (float v : color.pixels) nonFinite += !std::isfinite(v), negative += v < 0.0f;
  fmt::print(stderr, "dndenoise: {}: {}x{}, {} NaN/Inf and {} negative values (treated as 0)\n",
             name, color.width, color.height, nonFinite, negative);
}

void checkAgainstReference(const Options& o, const Image& ref, const Image& result, int& status) {
  auto values = metrics::compare(ref, result, {o.maxErrorMetric}).values;
  double v = values.at(o.maxErrorMetric);
  bool worse = metrics::higherIsBetter(o.maxErrorMetric) ? !(v >= o.maxError) : !(v <= o.maxError);
  fmt::print(stderr, "dndenoise: {} against {}: {:.6g} (limit {:.6g}){}\n", o.maxErrorMetric,
             o.reference, v, o.maxError, worse ? " FAILED" : "");
  if (worse) status = cli::kExitThreshold;
}

// -v: the light passes found, the rule and how closely the denoised ones recombine.
void reportPasses(const std::string& name, const PassesResult& passes) {
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
}

// One line, exit 1, for an option given that the loaded model has no use for.
void checkOptionsApply(const Options& o, const Denoiser& denoiser) {
  const ModelInfo& info = denoiser.info();
  const bool oidn = denoiser.overOidnBase();
  const bool control = oidn && info.has_control;
  const bool diffusionControl = control && info.oidn.control.diffusion;
  for (const auto& [flag, scope] : o.given) {
    const char* needs = nullptr;
    if (scope == OptionScope::OidnBase && !oidn)
      needs = "models over OIDN's networks, such as the default";
    else if (scope == OptionScope::Control && !control)
      needs = "models with a Control Module, such as the default";
    else if (scope == OptionScope::DiffusionControl && !diffusionControl)
      needs = "models with a diffusion Control Module, such as the default";
    else if (scope == OptionScope::Diffusion && !diffusionControl && oidn)
      needs = "diffusion models: the default or the from-scratch model";
    else if (scope == OptionScope::Scratch && oidn)
      needs = "the from-scratch diffusion model (models/diffusion-scratch.dnm)";
    if (needs)
      throw cli::UsageError(
          fmt::format("{} applies only to {}; {} is not one (see --help)", flag, needs, o.model));
  }
}

// Which of the frame's buffers the network saw, and which it had no use for.
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

void checkModelInputs(const Denoiser& denoiser, const std::string& name,
                      const std::vector<std::string>& has) {
  if (denoiser.missingBuffers(has).empty()) return;
  std::string needs, hasList;
  for (const auto& b : denoiser.info().input_buffers) needs += (needs.empty() ? "" : ", ") + b;
  for (const auto& b : has) hasList += (hasList.empty() ? "" : ", ") + b;
  throw IoError(fmt::format(
      "{}: the model needs {}; the file has {} (enable Denoising Data and the light passes, or "
      "map channels with --channels)",
      name, needs, hasList));
}

// The names in `available` that --buffers allows (all when it is not given).
std::vector<std::string> allowed(const Options& o, std::vector<std::string> available) {
  if (o.buffers.empty()) return available;
  available.erase(std::remove_if(available.begin(), available.end(),
                                 [&](const std::string& b) {
                                   return std::find(o.buffers.begin(), o.buffers.end(), b) ==
                                          o.buffers.end();
                                 }),
                  available.end());
  return available;
}

// What to read of `input`, from its header: the colour and the buffers the model
// needs (one line naming what it lacks).
ReadOptions readInputHeader(const Options& o, const Denoiser& denoiser, const std::string& input) {
  ReadOptions read = o.read;
  const std::vector<std::string> has = allowed(o, availableBuffers(input, read));
  // Without a colour, readFrame says what is wrong.
  if (std::find(has.begin(), has.end(), "color") != has.end()) {
    checkModelInputs(denoiser, input, has);
    read.only = denoiser.buffersToRead(has, o.denoise);
  }
  return read;
}

// Only the buffers the model reads: the file's other layers are copied from it
// when the result is written, and holding them as float would cost 1.5 GB on a
// 4K frame with all of Cycles' passes.
FrameBuffers readInput(const Options& o, const Denoiser& denoiser, const std::string& input,
                       const std::string& name) {
  if (input.empty()) {
    FrameBuffers frame = readSeparateFiles(o.separateFiles);
    for (const auto& b : frame.names())
      if (allowed(o, {b}).empty()) frame.buffers.erase(b);
    checkModelInputs(denoiser, name, frame.names());
    return frame;
  }
  return readFrame(input, readInputHeader(o, denoiser, input));
}

// The reference of --ref, read before any work; its size must match every input.
Image readReference(const Options& o) {
  Image ref = readImage(o.reference, 3);
  countAndZeroNonFinite(ref);
  return ref;
}

void checkReferenceSize(const Options& o, const Image& ref, const FrameBuffers& frame,
                        const std::string& name) {
  if (ref.width != frame.width || ref.height != frame.height)
    throw IoError(fmt::format("{}: is {}x{} but the reference {} is {}x{}", name, frame.width,
                              frame.height, o.reference, ref.width, ref.height));
}

int run(Options o, int argc, char** argv) {
  auto jobs = planJobs(o);
  const std::vector<std::string> previews = planPreviews(o, jobs);
  const std::optional<tonemap::OcioDisplay> display = displayFor(o, jobs);
  checkFilesBeforeWork(o, jobs, previews);
  // Freed activations are reused, not handed back to the kernel to be zeroed
  // again, within the peak the networks reach anyway (dn/nn/reusing_allocator.h).
  useReusingCpuAllocator(static_cast<std::size_t>(o.denoise.maxMemoryBytes));
  const auto loadStart = Clock::now();
  // The checksum for the outputs' metadata, on the core the loading leaves idle.
  auto modelSha256 = std::async(std::launch::async, [&] { return sha256OfFile(o.model); });
  Denoiser denoiser = [&] {
    try {
      return Denoiser::fromFile(o.model);
    } catch (const ModelError& e) {
      throw IoError(e.what());
    }
  }();
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

  o.temporal.read = o.read;
  o.temporal.filter.threads = torch::get_num_threads();
  std::vector<std::string> jobInputs;
  for (const auto& job : jobs) jobInputs.push_back(job.first);
  std::string frameByFrame;
  auto temporal = cli::TemporalSequence::plan(o.inputs, jobInputs, o.temporal, frameByFrame);
  if (!frameByFrame.empty()) fmt::print(stderr, "dndenoise: {}\n", frameByFrame);

  int status = cli::kExitOk;
  std::optional<cli::Progress> progress;
  if (o.verbose) progress.emplace(stderr);
  for (std::size_t j = 0; j < jobs.size(); ++j) {
    const auto& [input, output] = jobs[j];
    const std::string name = input.empty() ? o.separateFiles.at("color") : input;
    FrameBuffers frame = readInput(o, denoiser, input, name);
    if (!ref.empty()) checkReferenceSize(o, ref, frame, name);
    if (o.verbose) {
      for (const auto& note : frame.notes) fmt::print(stderr, "dndenoise: {}: {}\n", name, note);
      reportInputStatistics(name, frame.get("color"));
    }

    DenoiseOptions options = o.denoise;
    options.device = torch::Device(o.device);
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
    std::vector<double> times;
    DenoiseResult result;
    for (int r = 0; r < o.repeats; ++r) {
      const auto t0 = Clock::now();
      try {
        result =
            temporal
                ? temporal->denoise(
                      input, frame,
                      [&](const std::string& path) { return readInput(o, denoiser, path, path); },
                      [&](const std::string&, const FrameBuffers& f) {
                        return denoiser.denoise(f, options);
                      })
                : denoiser.denoise(frame, options);
      } catch (const std::invalid_argument& e) {
        throw IoError(fmt::format("{}: {}", name, e.what()));
      }
      times.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
    }
    if (progress) progress->finish();
    if (o.verbose && temporal) fmt::print(stderr, "dndenoise: {}: {}\n", name, temporal->report());
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
                 o.denoise.bfloat16 ? ", bfloat16" : "", result.exposure, result.steps,
                 result.tileCount, result.tileSize, times[times.size() / 2], times.size(),
                 times[times.size() / 2] / (frame.width * double(frame.height) / 1e6));
    } else if (o.verbose || o.repeats > 1) {
      std::sort(times.begin(), times.end());
      fmt::print(
          stderr,
          "dndenoise: {}: {} spp, exposure x{:.3g}, {}, skip {}, {} steps, mean matching {:.2g} "
          "px, {} tile(s) of {} px, {:.2f} s (median of {}), {:.2f} s/MPix\n",
          name, result.plan->spp > 0 ? std::to_string(result.plan->spp) : "unknown",
          result.exposure,
          result.plan->noise >= 0 ? fmt::format("noise {:.3g} (x{:.2f} the model's)",
                                                result.plan->noise, result.plan->noiseScale)
                                  : std::string("noise not measured"),
          result.plan->skip, result.steps, result.plan->meanMatchSigma, result.tileCount,
          result.tileSize, times[times.size() / 2], times.size(),
          times[times.size() / 2] / (frame.width * double(frame.height) / 1e6));
    }

    // Nothing non-finite leaves the tool: overflow becomes the largest float.
    const std::size_t clamped =
        cli::clampToFinite(result.color) + cli::clampToFinite(result.uncertainty);
    if (clamped > 0)
      fmt::print(stderr, "dndenoise: {}: {} values beyond the float range clamped\n", name,
                 clamped);
    std::optional<PassesResult> passes;
    if (o.passes) {
      passes = denoisePassesOfFile(passBase, input, frame, result.color, passOptionsFor(options));
      if (o.verbose) reportPasses(name, *passes);
    }
    const OutputKind kind = outputKindFor(output, o.floatOut);
    if (kind == OutputKind::Display) {
      writeDisplayImage(output, result.color, *display);
    } else {
      WriteOptions write = writeOptionsFor(frame);  // its data window and alpha
      // A sun or lamp above half's range (65504) would be written as Inf.
      write.half = !o.floatOut && fitsHalf(result.color);
      if (o.verbose && !o.floatOut && !write.half)
        fmt::print(stderr, "dndenoise: {}: values above the half range, result written as float\n",
                   name);
      write.rgbOnly = o.rgbOnly || input.empty() || kind == OutputKind::LinearRgb;
      write.layer = layerPrefixOf(frame) + o.layer;
      if (!result.uncertainty.empty() && !write.rgbOnly)
        write.extraLayers[layerPrefixOf(frame) + "uncertainty"] = result.uncertainty;
      if (passes) {  // float, so that the rule holds in the file too
        write.half = false;
        write.extraLayers.insert(passes->layers.begin(), passes->layers.end());
      }
      writeResult(input.empty() ? name : input, output, result.color, write, o.inplace);
    }
    if (!previews.empty()) writeDisplayImage(previews[j], result.color, *display);
    if (o.verbose)
      fmt::print(stderr, "dndenoise: wrote {}{}\n", output,
                 previews.empty() ? "" : " and " + previews[j]);
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
