#include "dndenoise/options.h"

#include <fmt/format.h>
#include <torch/torch.h>
#include <torch/version.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <thread>

#include "common/app.h"
#include "common/cli.h"
#include "dn/diffusion/refine.h"
#include "dn/io/frame_pattern.h"
#include "dn/metrics.h"
#include "dn/parallel.h"

namespace dn::dndenoise {

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
result is averaged with its neighbours' where they agree, and so is its noisy
render before a second denoising (--temporal).
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
  --precision float|bf16|fp16  the convolutions inside the networks in float
                      (default: OIDN's result), bfloat16 (faster on CPUs with AMX,
                      0.03 dB lower on average; docs/dndenoise.md, Speed and memory)
                      or half (fp16, as OIDN's CUDA device: with --device cuda only);
                      not given, --passes on a sequence runs its second
                      denoisings in bf16 where the CPU computes it natively
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
  --temporal on|filter|off
                      sequences with motion vectors (Blender's Vector pass, motion
                      blur off; Arnold/Karma motionvector, V-Ray VRayVelocity,
                      RenderMan motionBack/Fore): on (the default) averages each
                      frame's result with its neighbours' where the motion, the
                      features and the light agree, accumulates their noisy
                      renders the same way, denoises that too and blends the
                      two; filter: the average of results alone (one network
                      pass a frame, not two); off: every frame alone
  --window N          neighbours on each side for --temporal, 1-8 (default 4);
                      near a shot's ends, those one side lacks are taken
                      from the other (2N+1 frames wherever the shot has them)
  --temporal-trust learned|rules
                      how --temporal weighs each neighbour per pixel: the
                      hand-set light and colour tests (rules, the default), or
                      those scaled down by the small network the model file
                      carries (learned: less lost where a moving surface's
                      reflections or a sweeping shadow do not follow the
                      motion, less gained where all stands still)
  --temporal-filter auto|cpu|tensors
                      where --temporal's filter runs: the CPU's per-pixel code
                      (cpu), or tensor operations on --device with the window's
                      frames kept there (tensors: float32, within about 1e-6 of
                      cpu's); auto (the default): tensors with --device cuda,
                      else cpu
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
  --passes-temporal light|all|off
                      on a sequence with motion vectors: the light passes
                      filtered over time with the beauty's weights, their
                      renders accumulated and denoised again as its are, and
                      Diffuse Color filtered too, the residual closing the sum
                      (light, default); the colour passes of view-dependent
                      light too (all); every pass as denoised alone (off)
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
  --maxmem MB         memory budget for network activations, >= 100 (default 3000;
                      with --device cuda: half the GPU's free memory)
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

}  // namespace

bool Options::wasGiven(const std::string& flag) const {
  return std::any_of(given.begin(), given.end(),
                     [&](const GivenOption& option) { return option.flag == flag; });
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
      const auto precision = precisionFromName(v);
      if (!precision) throw cli::UsageError("--precision must be float, bf16 or fp16, got " + v);
      o.denoise.precision = *precision;
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
      parseFrameRange(o.frames);
    } else if (args.flag("--skip-missing")) {
      o.skipMissing = true;
    } else if (args.flag("--temporal")) {
      const std::string v = args.value("--temporal");
      if (v != "on" && v != "filter" && v != "off")
        throw cli::UsageError("--temporal must be on, filter or off, got " + v);
      o.temporal = v != "off";
      o.sequence.filter.accumulatedShare =
          v == "filter" ? 0.0 : temporal::TemporalOptions().accumulatedShare;
    } else if (args.flag("--temporal-filter")) {
      o.temporalFilter = args.value("--temporal-filter");
      if (o.temporalFilter != "auto" && o.temporalFilter != "cpu" && o.temporalFilter != "tensors")
        throw cli::UsageError("--temporal-filter must be auto, cpu or tensors, got " +
                              o.temporalFilter);
    } else if (args.flag("--temporal-trust")) {
      o.temporalTrust = args.value("--temporal-trust");
      if (o.temporalTrust != "learned" && o.temporalTrust != "rules")
        throw cli::UsageError("--temporal-trust must be learned or rules, got " + o.temporalTrust);
    } else if (args.flag("--window")) {
      o.sequence.radius = args.intValue("--window", 1, 8);
    } else if (args.flag("--motion")) {
      o.sequence.motion = args.value("--motion");
    } else if (args.flag("--rgb-only")) {
      o.rgbOnly = true;
    } else if (args.flag("--float")) {
      o.floatOut = true;
    } else if (args.flag("--inplace")) {
      o.inplace = true;
    } else if (args.flag("--passes")) {
      o.passes = true;
      o.given.push_back({"--passes", OptionScope::OidnBase});
    } else if (args.flag("--passes-temporal")) {
      const std::string v = args.value("--passes-temporal");
      if (v != "light" && v != "all" && v != "off")
        throw cli::UsageError("--passes-temporal must be light, all or off, got " + v);
      o.passesOverTime = v == "light" ? PassesOverTime::Light
                         : v == "all" ? PassesOverTime::All
                                      : PassesOverTime::Off;
      o.passesTemporalGiven = true;
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
      o.denoise.budgetFromFreeMemory = false;  // on a GPU too
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
  if (o.passesTemporalGiven && !o.passes) throw cli::UsageError("--passes-temporal needs --passes");
  if (o.passes && (o.rgbOnly || !o.separateFiles.empty()))
    throw cli::UsageError(
        "--passes needs a multilayer EXR input and output, not --rgb-only or "
        "separate buffer files");
  if (o.device != "cpu" && o.device != "cuda")
    throw cli::UsageError("--device must be cpu or cuda");
  if (o.device == "cuda" && !torch::cuda::is_available())
    throw cli::UsageError("--device cuda: no CUDA device is available to this LibTorch build");
  if (o.denoise.precision == Precision::Float16 && o.device != "cuda")
    throw cli::UsageError(
        "--precision fp16 runs on CUDA only (--device cuda); on the CPU: "
        "float or bf16");
  if (o.model.empty()) o.model = cli::defaultModelPath();
  return o;
}

void checkOptionsApply(const Options& o, const Denoiser& denoiser) {
  const ModelInfo& info = denoiser.info();
  const bool oidn = denoiser.overOidnBase();
  const bool control = oidn && info.has_control;
  const bool diffusionControl = control && info.oidn.control.diffusion;
  if (o.temporalTrust == "learned" && !info.notes.count("temporal_trust"))
    throw cli::UsageError("--temporal-trust learned: " + o.model +
                          " carries no learned trust (dntrain defaults --temporal-trust)");
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

}  // namespace dn::dndenoise
