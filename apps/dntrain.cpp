// dntrain: trains the diffusion denoiser.
//   dntrain base    --data DIR --photos DIR --out base.dnm     pretrain the prior
//   dntrain control --data DIR --base base.dnm --out model.dnm  train the Control Module
//   dntrain regression --data DIR --base base.dnm --out reg.dnm the single-pass ablation
//   dntrain defaults --model M --respacing 27 --default-skip 18 --default-spp 4 ...  tuned defaults
//   dntrain trust --data DIR --out trust.txt    the temporal filter's learned trust
#include <fmt/format.h>
#include <torch/torch.h>
#include <torch/version.h>

#include <ATen/CPUGeneratorImpl.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <set>
#include <thread>

#include "common/app.h"
#include "common/cli.h"
#include "common/progress.h"
#include "common/version.h"
#include "dn/diffusion/refine.h"
#include "dn/diffusion/sampler.h"
#include "dn/infer/control_inputs.h"
#include "dn/infer/denoiser.h"
#include "dn/io/buffer_io.h"
#include "dn/io/output_files.h"
#include "dn/nn/control_module.h"
#include "dn/nn/model_inputs.h"
#include "dn/nn/oidn_import.h"
#include "dn/train/control_loss.h"
#include "dn/train/distributed.h"
#include "dn/train/trainer.h"
#include "dn/train/training_data.h"
#include "dn/train/trust_trainer.h"

namespace fs = std::filesystem;
using namespace dn;
using Clock = std::chrono::steady_clock;

namespace {

const char* kUsage =
    R"(usage: dntrain base    --data DIR [--photos DIR ...] --out base.dnm [options]
       dntrain control --data DIR --base base.dnm|--init model.dnm --out model.dnm [options]
       dntrain regression --data DIR --base base.dnm --out reg.dnm [options]
       dntrain defaults --model FILE [--respacing SPEC] [--default-skip S] [--default-spp N]
                        [--exposure-target Y] [--noise-reference RENDER ...]
                        [--temporal-trust FILE] [--out FILE]
       dntrain trust   --data DIR[,DIR...] --out trust.txt [--steps N] [--batch N] [--lr X]
       dntrain prior --model model.dnm --out base.dnm
       dntrain rebase --model model.dnm --base oidn.dnm --out model2.dnm
       dntrain import-oidn [--lib PATH] [--variant default|small|large] --out FILE

base     pretrains the pixel-space prior on clean images (the data set's ground
         truths and photographs) conditioned on a degraded copy of each.
control  freezes a pretrained prior and trains the Control Module on the data
         set's low-spp renders and feature buffers against the clean targets.
         With --base models/oidn.dnm (OIDN's networks): a Control Module over the
         frozen colour + albedo + normal network, fed the --aux buffers it does
         not see (any may be missing from a frame), the diffusion state and its
         noise level; dndenoise refines the base's estimate in --sigmas steps.
         regression trains the same module in one pass, without the state.
regression  the ablation: the same networks (prior + Control Module, initialised
         from the prior, all weights trained) map the render to the clean image
         in one pass, trained with L1; dndenoise runs it in one network step.
defaults sets the sampling a model file gives dndenoise when no --steps/--skip
         are passed (after tuning them on a validation split); rewrites --model
         in place unless --out is given. The weights are not touched.
trust    fits the temporal filter's learned trust (experiments/temporal_trust/)
         on the animated scenes under each --data (scenegen/animate.py, then
         experiments/temporal_trust/prepare.py): every scene's dump4/ and
         dump16/; scenes whose number ends in 4 or 9 are held out to validate.
         Prints the loss of each frame alone, of the rules that made the dumps
         and of the fitted trust; writes it as one line (defaults
         --temporal-trust puts it into a model file). Defaults: --steps 4000
         --batch 16384 --lr 3e-3.
rebase   moves the Control Module of a model over the OIDN base onto another
         import of that base (with more networks, e.g. the prefilter mode's):
         the network it steers must hold exactly the same weights.
prior    writes the frozen prior inside a controlled model as a model of its own
         (the "no Control Module" ablation), with the same sampling defaults.
import-oidn  converts the pretrained networks inside OIDN's core library (found in
         the installed pyoidn unless --lib is given) into a model file: one
         network for colour, colour + albedo, and colour + albedo + normal, with
         the library, its version, each blob's offset and sha256 in the metadata.
         --variant large holds OIDN's one large network, trained on clean aux.

options:
  --data DIR[,DIR...]   data set roots (docs/dataset.md); training uses split 'train'
  --photos DIR          folder of photographs for the prior (repeatable)
  --base FILE           pretrained prior (control, regression)
  --init FILE           control, regression: continue training the Control Module of
                        this model (its base stays frozen; its sampling defaults are
                        kept); regression only over the OIDN base
  --out FILE            model file written at the end (EMA weights)
  --aux LIST|default|none  control inputs (default: Denoising Data + diffuse/glossy/
                        transmission light passes); none = the radiance-only ablation
  --sigmas LIST         control over OIDN: the noise levels dndenoise refines at,
                        noisiest first (default 0.05,0.02)
  --hint-channels N     control over OIDN: width of the hint network (default 32)
  --steer SET           control over OIDN: the base network the module steers:
                        hdr_alb_nrm (default; noisy albedo and normal) or
                        hdr_calb_cnrm_large (OIDN's prefilter mode: albedo and normal
                        cleaned by the base's own networks first)
  --steps N             total optimizer steps, >= 1 (default 2000); raise it and --resume
                        to extend
  --batch N             batch size, 1-1024 (default 8)
  --crop N              crop size, 16-4096 (default 64)
  --spp LIST            input sample counts, each >= 1 (default 4,16,32: the
                        training set's 8 stacks of 4 spp)
  --lr X                learning rate in (0, 1] (default 2e-4)
  --halve-every N       halve lr every N steps (default 0: never)
  --ema X               EMA decay in [0, 1) (default 0.999)     --seed N  >= 0 (default 1)
  --prediction eps|v    network output (default eps)
  --max-timestep T      draw training timesteps below T (0-1000) only (default: all 1000);
                        dndenoise never starts above its largest skip's step
  --render-start P      control: fraction of samples noised from the render itself,
                        at a step that covers its noise, as dndenoise starts (default 0)
  --base-channels N --res-blocks N   prior size, 4-1024 and 1-16 (base only; default: the
                        UNet defaults)
  --default-skip S      skip stored in the model for dndenoise, 0-999 (default: 18
                        control, 0 base)
  --respacing SPEC      defaults: steps stored in the model for dndenoise ("27", "super27")
  --default-spp N       defaults: the spp the default skip was tuned at; dndenoise
                        scales skip and mean matching to other spp from it
  --exposure-target Y   defaults: dndenoise scales each frame so the mean of its
                        luminance (clamped to 6) is Y
  --noise-reference FILE  defaults (repeatable): renders like those the default skip
                        was tuned on; their mean measured noise becomes the model's
                        noise_reference, and dndenoise scales skip and mean
                        matching by each render's measured noise relative to it
  --model FILE          defaults: the model file to change
  --temporal-trust FILE defaults: the learned trust (dntrain trust's --out) that
                        dndenoise's temporal filter weighs neighbours by
  --lib PATH            import-oidn: libOpenImageDenoise_core.so.* to read
  --variant NAME        import-oidn: network size, default (0.92 M parameters),
                        small (0.32 M) or large (3.85 M) (default: default)
  --val-every N         validation every N steps (default 250; 0 disables)
  --log FILE            JSON-lines log (default: OUT.log.jsonl)
  --checkpoint FILE     checkpoint path (default: OUT.ckpt)
  --checkpoint-minutes M  checkpoint interval (default 5)
  --resume              continue from the checkpoint if it exists (same data order)
  --threads N           CPU threads for the network and the loader, 1-1024
  --cache-gb N          decoded frames kept in memory (default 4); a set that does not
                        fit is decoded again and again, several times slower
  --world-size N --rank R  data-parallel training over N processes (default 1 0):
                        each rank draws its own --batch (global batch N x batch) and
                        gradients are averaged; rank 0 writes log, checkpoint, model
  --master-addr HOST --master-port P  where rank 0 listens (default 127.0.0.1 29500)
                        without these flags: env WORLD_SIZE, RANK, MASTER_ADDR, MASTER_PORT
  --version             versions of the tool and its libraries
  -h, --help
Ctrl-C (SIGINT) or SIGTERM saves a checkpoint and exits with code 130.
)";

std::atomic<bool> stopRequested{false};
extern "C" void onSignal(int) { stopRequested = true; }

struct Options {
  std::string mode, data, base, init, out, log, checkpoint, model, respacing, lib, temporalTrust;
  std::string variant = "default";
  std::vector<std::string> photos, noiseReference;
  std::string aux = "default", prediction = "eps", sigmas = "0.05,0.02";
  std::string steer = "hdr_alb_nrm";
  int64_t hintChannels = 32;
  int64_t cacheGb = 4;
  std::vector<int> spp = {4, 16, 32};  // the training set's 8 stacks of 4 spp
  int64_t steps = 2000, batch = 8, crop = 64, halveEvery = 0, valEvery = 250, baseChannels = 0,
          resBlocks = 0, defaultSkip = -1, defaultSpp = -1;
  double exposureTarget = -1.0, renderStart = 0.0;
  int64_t maxTimestep = 0;
  double lr = 2e-4, ema = 0.999, checkpointMinutes = 5;
  std::set<std::string> given;  // of --steps, --batch, --lr: those on the command line
  uint64_t seed = 1;
  int threads = 0;
  bool resume = false;
  int worldSize = 1, rank = 0, masterPort = 29500;
  std::string commandLine;  // recorded in the model files written
  std::string masterAddr = "127.0.0.1";
};

// The launcher convention (torchrun's names) as defaults for the distributed flags.
void distributedDefaultsFromEnvironment(Options& o) {
  auto env = [](const char* name) {
    return std::getenv(name) ? std::string(std::getenv(name)) : "";
  };
  if (!env("WORLD_SIZE").empty()) o.worldSize = cli::Args::toInt("WORLD_SIZE", env("WORLD_SIZE"));
  if (!env("RANK").empty()) o.rank = cli::Args::toInt("RANK", env("RANK"));
  if (!env("MASTER_ADDR").empty()) o.masterAddr = env("MASTER_ADDR");
  if (!env("MASTER_PORT").empty())
    o.masterPort = cli::Args::toInt("MASTER_PORT", env("MASTER_PORT"));
}

// Rank 0 keeps the single-process data stream; the others draw their own.
uint64_t rankSeed(uint64_t seed, int rank) {
  return rank == 0 ? seed : seed + 0x9E3779B97F4A7C15ull * static_cast<uint64_t>(rank);
}

std::vector<std::string> withModel(std::vector<std::string> files, const std::string& model) {
  files.push_back(model);
  return files;
}

Options parseArgs(int argc, char** argv) {
  cli::Args args(argc, argv);
  Options o;
  o.commandLine = cli::commandLine(argc, argv);
  distributedDefaultsFromEnvironment(o);
  while (!args.done()) {
    if (args.flag("-h", "--help")) {
      std::fputs(kUsage, stdout);
      std::exit(cli::kExitOk);
    } else if (args.flag("--version")) {
      auto components = cli::commonComponents();
      components.emplace_back("LibTorch", TORCH_VERSION);
      std::fputs(cli::versionText("dntrain", components).c_str(), stdout);
      std::exit(cli::kExitOk);
    } else if (args.flag("--data"))
      o.data = args.value("--data");
    else if (args.flag("--photos"))
      o.photos.push_back(args.value("--photos"));
    else if (args.flag("--base"))
      o.base = args.value("--base");
    else if (args.flag("--init"))
      o.init = args.value("--init");
    else if (args.flag("--out"))
      o.out = args.value("--out");
    else if (args.flag("--aux"))
      o.aux = args.value("--aux");
    else if (args.flag("--sigmas"))
      o.sigmas = args.value("--sigmas");
    else if (args.flag("--steer"))
      o.steer = args.value("--steer");
    else if (args.flag("--hint-channels"))
      o.hintChannels = args.intValue("--hint-channels", 1, 1024);
    else if (args.flag("--cache-gb"))
      o.cacheGb = args.intValue("--cache-gb", 1, 1024);
    else if (args.flag("--steps"))
      o.steps = args.intValue("--steps", 1, INT32_MAX), o.given.insert("--steps");
    else if (args.flag("--batch"))
      o.batch = args.intValue("--batch", 1, 1 << 20), o.given.insert("--batch");
    else if (args.flag("--crop"))
      o.crop = args.intValue("--crop", 16, 4096);
    else if (args.flag("--spp"))
      o.spp = cli::intList("--spp", args.value("--spp"), 1, 1 << 24);
    else if (args.flag("--lr"))
      o.lr = args.doubleValue("--lr", 1e-12, 1.0), o.given.insert("--lr");
    else if (args.flag("--halve-every"))
      o.halveEvery = args.intValue("--halve-every", 0, INT32_MAX);
    else if (args.flag("--ema"))
      o.ema = args.doubleValue("--ema", 0.0, 0.999999);
    else if (args.flag("--seed"))
      o.seed = static_cast<uint64_t>(args.intValue("--seed", 0, INT32_MAX));
    else if (args.flag("--max-timestep"))
      o.maxTimestep = args.intValue("--max-timestep", 0, 1000);
    else if (args.flag("--render-start"))
      o.renderStart = args.doubleValue("--render-start", 0.0, 1.0);
    else if (args.flag("--prediction"))
      o.prediction = args.value("--prediction");
    else if (args.flag("--base-channels"))
      o.baseChannels = args.intValue("--base-channels", 4, 1024);
    else if (args.flag("--res-blocks"))
      o.resBlocks = args.intValue("--res-blocks", 1, 16);
    else if (args.flag("--default-skip"))
      o.defaultSkip = args.intValue("--default-skip", 0, 999);
    else if (args.flag("--exposure-target"))
      o.exposureTarget = args.doubleValue("--exposure-target");
    else if (args.flag("--noise-reference"))
      o.noiseReference.push_back(args.value("--noise-reference"));
    else if (args.flag("--default-spp"))
      o.defaultSpp = args.intValue("--default-spp", 1, 1 << 24);
    else if (args.flag("--respacing"))
      o.respacing = args.value("--respacing");
    else if (args.flag("--model"))
      o.model = args.value("--model");
    else if (args.flag("--temporal-trust"))
      o.temporalTrust = args.value("--temporal-trust");
    else if (args.flag("--lib"))
      o.lib = args.value("--lib");
    else if (args.flag("--variant"))
      o.variant = args.value("--variant");
    else if (args.flag("--val-every"))
      o.valEvery = args.intValue("--val-every", 0, INT32_MAX);
    else if (args.flag("--log"))
      o.log = args.value("--log");
    else if (args.flag("--checkpoint"))
      o.checkpoint = args.value("--checkpoint");
    else if (args.flag("--checkpoint-minutes"))
      o.checkpointMinutes = args.doubleValue("--checkpoint-minutes", 0.0, 1e6);
    else if (args.flag("--resume"))
      o.resume = true;
    else if (args.flag("--threads"))
      o.threads = args.intValue("--threads", 1, 1024);
    else if (args.flag("--world-size"))
      o.worldSize = args.intValue("--world-size", 1, 4096);
    else if (args.flag("--rank"))
      o.rank = args.intValue("--rank", 0, 4095);
    else if (args.flag("--master-addr"))
      o.masterAddr = args.value("--master-addr");
    else if (args.flag("--master-port"))
      o.masterPort = args.intValue("--master-port", 1, 65535);
    else if (args.peek().size() > 1 && args.peek()[0] == '-')
      throw cli::UsageError("unknown option '" + args.peek() + "' (see --help)");
    else if (o.mode.empty())
      o.mode = args.positional();
    else
      throw cli::UsageError("unexpected argument '" + args.peek() + "'");
  }
  if (o.mode == "defaults") {
    if (o.model.empty()) throw cli::UsageError("defaults needs --model");
    if (o.respacing.empty() && o.defaultSkip < 0 && o.defaultSpp < 0 && o.exposureTarget == -1.0 &&
        o.noiseReference.empty() && o.temporalTrust.empty())
      throw cli::UsageError(
          "defaults needs one of --respacing, --default-skip, --default-spp, --exposure-target, "
          "--noise-reference, --temporal-trust");
    if (o.exposureTarget != -1.0 && !(o.exposureTarget > 0.0 && o.exposureTarget < 6.0))
      throw cli::UsageError("--exposure-target must be in (0, 6)");
    if (o.out.empty()) o.out = o.model;
    // Only the sampling defaults change: rewriting --model in place is the default.
    std::vector<std::string> inputs = withModel(o.noiseReference, o.model);
    if (!o.temporalTrust.empty()) inputs.push_back(o.temporalTrust);
    cli::checkFiles(inputs, {{o.out, o.model}}, cli::Inplace::Allow);
    return o;
  }
  if (o.mode == "trust") {
    if (o.data.empty() || o.out.empty()) throw cli::UsageError("trust needs --data and --out");
    if (o.batch < 1 || o.steps < 1) throw cli::UsageError("--batch and --steps must be positive");
    cli::checkFiles({}, {{o.out, "--out"}});
    return o;
  }
  if (o.mode == "prior") {
    if (o.model.empty() || o.out.empty()) throw cli::UsageError("prior needs --model and --out");
    cli::checkFiles({o.model}, {{o.out, o.model}});
    return o;
  }
  if (o.mode == "rebase") {
    if (o.model.empty() || o.base.empty() || o.out.empty())
      throw cli::UsageError("rebase needs --model, --base and --out");
    cli::checkFiles({o.model, o.base}, {{o.out, o.model}});
    return o;
  }
  if (o.mode == "import-oidn") {
    if (o.out.empty()) throw cli::UsageError("import-oidn needs --out FILE");
    try {
      oidnArchFromName(o.variant);
    } catch (const std::invalid_argument& e) {
      throw cli::UsageError(std::string("--variant: ") + e.what());
    }
    return o;
  }
  if (o.mode != "base" && o.mode != "control" && o.mode != "regression")
    throw cli::UsageError(
        "first argument must be base, control, regression, defaults, trust, prior, rebase or "
        "import-oidn (see --help)");
  if (o.out.empty()) throw cli::UsageError("--out is required");
  if (o.mode != "base" && (o.base.empty() == o.init.empty() || o.data.empty()))
    throw cli::UsageError(o.mode + " needs --data and one of --base or --init");
  if (!o.init.empty() && o.mode == "base")
    throw cli::UsageError("--init continues a controlled model: control or regression");
  try {
    oidnInputSet(o.steer);
  } catch (const std::invalid_argument& e) {
    throw cli::UsageError(std::string("--steer: ") + e.what());
  }
  if (o.maxTimestep < 0 || !(o.renderStart >= 0.0 && o.renderStart <= 1.0))
    throw cli::UsageError("--max-timestep must be >= 0 and --render-start in [0, 1]");
  if (o.mode == "base" && o.data.empty() && o.photos.empty())
    throw cli::UsageError("base needs --data and/or --photos");
  if (o.batch > 1024) throw cli::UsageError("--batch must be at most 1024");
  if (o.batch < 1 || o.crop < 16 || o.steps < 1)
    throw cli::UsageError("--batch, --crop and --steps must be positive (crop >= 16)");
  if (o.prediction != "eps" && o.prediction != "v")
    throw cli::UsageError("--prediction must be eps or v");
  if (o.rank >= o.worldSize)
    throw cli::UsageError(
        fmt::format("--rank {} must be below --world-size {}", o.rank, o.worldSize));
  if (o.log.empty()) o.log = o.out + ".log.jsonl";
  if (o.checkpoint.empty()) o.checkpoint = o.out + ".ckpt";
  // Never overwrite the model training starts from; a resumed run rewrites its
  // own checkpoint, which is not an input here.
  std::vector<std::string> models;
  for (const auto& m : {o.base, o.init})
    if (!m.empty()) models.push_back(m);
  cli::checkFiles(models, {{o.out, "--out"}, {o.log, "--log"}, {o.checkpoint, "--checkpoint"}});
  return o;
}

std::vector<std::string> auxBuffers(const std::string& spec) {
  if (spec == "default") return defaultAuxBuffers();
  if (spec == "none") return {};
  auto list = cli::splitList(spec);
  auxChannelCount(list);  // validates the names
  return list;
}

// Which tool and command wrote a model file, as image outputs carry it. Not for
// trained models: a checkpoint resumes only with the notes it was written with.
void stampProvenance(ModelInfo& info, const Options& o) {
  info.notes["software"] = fmt::format("dntrain {} ({})", DN_PROJECT_VERSION, DN_GIT_DESCRIBE);
  info.notes["command"] = o.commandLine;
}

// A model continued with --init: the init file's provenance notes described how
// that file was written, not this one, so they give way to its name.
void markContinued(ModelInfo& info, const Options& o) {
  info.notes.erase("command");
  info.notes.erase("software");
  info.notes["init_model"] = fs::path(o.init).filename().string();
}

// The extra buffers a Control Module over the OIDN base reads: --aux, or the
// default aux buffers that the base does not see.
std::vector<std::string> extraBuffers(const std::string& spec, const OidnInputSet& set) {
  std::vector<std::string> extras;
  for (const auto& name : auxBuffers(spec))
    if (std::find(set.buffers.begin(), set.buffers.end(), name) == set.buffers.end())
      extras.push_back(name);
  return extras;
}

// control/regression over OIDN's networks: a new Control Module on the frozen
// base of --base, or the one of --init continued.
std::pair<ModelInfo, OidnControlled> buildOidnControlled(const Options& o, LoadedModel loaded) {
  ModelInfo info = loaded.info;
  if (!o.init.empty()) {
    if (!info.has_control) throw IoError(o.init + ": has no Control Module to continue");
    if (info.oidn.control.diffusion != (o.mode == "control"))
      throw IoError(o.init + ": was trained with the other objective");
    markContinued(info, o);
    return {info, loaded.oidnControlled};
  }
  if (info.has_control)
    throw IoError(o.base + ": already has a Control Module (continue it with --init)");
  OidnControlConfig& c = info.oidn.control;
  c.input_set = o.steer;
  const OidnInputSet& set = oidnInputSet(c.input_set);
  if (set.buffers.size() != 3)
    throw IoError("--steer " + o.steer + ": the module steers a colour + albedo + normal network");
  if (std::find(info.oidn.input_sets.begin(), info.oidn.input_sets.end(), c.input_set) ==
      info.oidn.input_sets.end())
    throw IoError(o.base + ": has no " + c.input_set + " network to steer");
  if (set.cleanAux && !loaded.oidn->canPrefilter())
    throw IoError(o.base + ": has no albedo and normal networks to clean " + c.input_set +
                  "'s inputs");
  c.extra_buffers = extraBuffers(o.aux, set);
  c.hint_channels = o.hintChannels;
  c.diffusion = o.mode == "control";
  info.has_control = true;
  info.objective = c.diffusion ? Objective::Diffusion : Objective::Regression;
  info.oidn.sigmas.clear();
  if (c.diffusion)
    for (const auto& item : cli::splitList(o.sigmas))
      info.oidn.sigmas.push_back(cli::Args::toDouble("--sigmas", item));
  checkSigmas(info.oidn.sigmas);
  info.input_buffers.assign(set.buffers.begin() + 1, set.buffers.end());
  info.input_buffers.insert(info.input_buffers.end(), c.extra_buffers.begin(),
                            c.extra_buffers.end());
  info.notes["base_model"] = fs::path(o.base).filename().string();
  return {info, OidnControlled(loaded.oidn, c)};
}

struct BuiltModel {
  ModelInfo info;
  std::shared_ptr<ConditionalDenoiser> model;  // the diffusion UNet family
  OidnControlled controlled{nullptr};          // over the OIDN base
};

void noteTrainingSettings(ModelInfo& info, const Options& o) {
  info.notes["train.mode"] = o.mode;
  info.notes["train.batch"] = std::to_string(o.batch);
  info.notes["train.crop"] = std::to_string(o.crop);
  info.notes["train.seed"] = std::to_string(o.seed);
  if (o.maxTimestep > 0) info.notes["train.max_timestep"] = std::to_string(o.maxTimestep);
  if (o.renderStart > 0) info.notes["train.render_start"] = fmt::format("{}", o.renderStart);
  if (o.worldSize > 1) info.notes["train.world_size"] = std::to_string(o.worldSize);
}

// The model to train, described by its ModelInfo (training options go in notes,
// so a checkpoint only resumes the run it belongs to).
BuiltModel buildModel(const Options& o) {
  if (o.mode != "base") {
    LoadedModel loaded = loadModelFile(o.init.empty() ? o.base : o.init);
    if (loaded.info.base_kind == BaseKind::Oidn) {
      auto [info, controlled] = buildOidnControlled(o, std::move(loaded));
      noteTrainingSettings(info, o);
      return {info, nullptr, controlled};
    }
  }
  ModelInfo info;
  std::shared_ptr<ConditionalDenoiser> model;
  if (o.mode == "base") {
    if (o.baseChannels > 0) info.base.base_channels = o.baseChannels;
    if (o.resBlocks > 0) info.base.res_blocks = o.resBlocks;
    info.has_control = false;
    info.prediction = predictionFromName(o.prediction == "eps" ? "epsilon" : "v");
    info.notes["default_skip"] = std::to_string(std::max<int64_t>(0, o.defaultSkip));
  } else if (!o.init.empty()) {
    // Fine-tuning: the file's prior stays frozen, its Control Module trains on,
    // and its sampling defaults are kept.
    if (o.mode != "control")
      throw IoError(o.init + ": regression --init continues a module over the OIDN base only");
    LoadedModel loaded = loadModelFile(o.init);
    if (!loaded.info.has_control) throw IoError(o.init + ": has no Control Module to continue");
    info = loaded.info;
    model = loaded.model;
    markContinued(info, o);
  } else {
    const LoadedModel base = loadModelFile(o.base);
    if (base.info.has_control) throw IoError(o.base + ": is a controlled model, not a base prior");
    info = base.info;
    info.has_control = true;
    info.input_buffers = auxBuffers(o.aux);
    info.control.aux_channels = auxChannelCount(info.input_buffers);
    info.notes["default_skip"] = std::to_string(o.defaultSkip >= 0 ? o.defaultSkip : 18);
    info.notes["base_model"] = fs::path(o.base).filename().string();
    model = std::make_shared<ControlledDenoiser>(base.prior(), info.control);
    if (o.mode == "regression") {
      info.objective = Objective::Regression;
      info.prediction = Prediction::X0;
      info.notes["default_skip"] = "0";
      for (auto& parameter : model->parameters()) parameter.set_requires_grad(true);
    }
  }
  noteTrainingSettings(info, o);
  if (!model) model = buildDenoiser(info);
  return {info, model, nullptr};
}

// The frames of a split in every root of a comma-separated --data list.
std::vector<data::FrameRecord> scanRoots(const std::string& roots, const std::string& split) {
  std::vector<data::FrameRecord> frames;
  for (const auto& root : cli::splitList(roots)) {
    auto more = data::scanDataset(root, split);
    frames.insert(frames.end(), more.begin(), more.end());
  }
  return frames;
}

// Produces the training batches of one mode, deterministically from (seed, step).
class BatchSource {
 public:
  BatchSource(const Options& o, const ModelInfo& info, const std::string& split, int64_t startStep)
      : o_(o),
        info_(info),
        seed_(rankSeed(o.seed, o.rank)),
        curve_(tonemap::curveFromName(info.tonemap)) {
    if (!o.photos.empty()) photos_ = std::make_unique<PhotoSource>(o.photos);
    if (!o.data.empty()) {
      data::SampleOptions so;
      so.task = o.mode == "base" ? data::Task::Clean : data::Task::Denoise;
      so.spp = o.spp;
      so.aux = info.input_buffers;
      so.crop = static_cast<int>(o.crop);
      so.missingAuxAsZero = info.base_kind == BaseKind::Oidn;  // renderers differ in passes
      data::LoaderOptions lo;
      lo.batchSize = static_cast<int>(renderedPerBatch());
      lo.seed = seed_;
      lo.threads = 2;
      lo.cacheBytes = std::size_t(o.cacheGb) << 30;
      loader_ = std::make_unique<data::Loader>(
          scanRoots(o.data, split), so, lo,
          static_cast<std::uint64_t>(startStep * renderedPerBatch()));
    }
  }

  TrainBatch batch(int64_t step) {
    if (info_.base_kind == BaseKind::Oidn) {
      // Linear, as rendered: the loss prepares every input as OIDN does.
      const data::Batch b = loader_->next();
      const int64_t extras = int64_t(info_.oidn.control.extra_buffers.size());
      const int64_t buffers = int64_t(info_.input_buffers.size());
      return {colorTensor(b), auxTensor(b), targetTensor(b),
              torch::tensor(b.present).view({b.size, buffers}).narrow(1, buffers - extras, extras)};
    }
    if (o_.mode != "base") return toTrainBatch(loader_->next(), info_.input_buffers, curve_);
    // base: clean images from renders and photographs, conditioned on a degraded copy.
    auto generator = at::detail::createCPUGenerator(seed_ * 1000003 + static_cast<uint64_t>(step));
    std::vector<torch::Tensor> clean;
    if (loader_) clean.push_back(targetTensor(loader_->next()));
    if (photos_) clean.push_back(photos_->draw(o_.batch - renderedPerBatch(), o_.crop, generator));
    torch::Tensor x = torch::cat(clean, 0);
    return {tonemapRadiance(degrade(x, generator), curve_), {}, tonemapRadiance(x, curve_), {}};
  }

 private:
  int64_t renderedPerBatch() const {
    if (o_.data.empty()) return 0;
    return o_.mode == "base" && !o_.photos.empty() ? o_.batch / 2 : o_.batch;
  }
  const Options& o_;
  const ModelInfo& info_;
  uint64_t seed_;
  tonemap::Curve curve_;
  std::unique_ptr<PhotoSource> photos_;
  std::unique_ptr<data::Loader> loader_;
};

// Denoises a fixed validation batch with the sampler dndenoise uses; L1 on
// [0, 6] radiance and PSNR on Reinhard, for the result and for the input.
std::string validate(Trainer& trainer, const TrainBatch& val, tonemap::Curve curve) {
  const ModelInfo& info = trainer.info();
  torch::Tensor out;
  if (info.objective == Objective::Regression) {
    torch::NoGradGuard noGrad;
    trainer.model()->eval();
    out = tonemappedFromModelSpace(
        regressDirect(*trainer.model(), modelSpaceFromTonemapped(val.noisy), val.aux).clamp(-1, 1));
  } else {
    SamplerOptions so;
    so.seed = 7;
    so.skip_steps = std::stoll(info.notes.at("default_skip"));
    out = denoiseTonemapped(*trainer.model(), info.samplingSchedule(), info.prediction, val.noisy,
                            val.aux, so);
  }
  auto hdr = [&](const torch::Tensor& t) { return inverseTonemapRadiance(t, curve); };
  auto l1 = [](const torch::Tensor& a, const torch::Tensor& b) {
    return (a - b).abs().mean().item<double>();
  };
  auto psnr = [](const torch::Tensor& a, const torch::Tensor& b) {
    auto mse = (a / (1 + a) - b / (1 + b)).pow(2).mean().item<double>();
    return 10 * std::log10(1 / mse);
  };
  torch::Tensor ref = hdr(val.target), result = hdr(out), input = hdr(val.noisy);
  return fmt::format(
      "\"val_loss\": {:.6g}, \"val_l1\": {:.6g}, \"val_psnr\": {:.4f}, \"input_l1\": {:.6g}, "
      "\"input_psnr\": {:.4f}",
      trainer.evaluate(val, 11), l1(result, ref), psnr(result, ref), l1(input, ref),
      psnr(input, ref));
}

// The Control Module's validation loss against the base alone on the same
// batch (L1 in the base's output space): what the control adds.
std::string validateControlled(Trainer& trainer, const TrainBatch& val) {
  const ModelInfo& info = trainer.info();
  const OidnInputSet& set = oidnInputSet(info.oidn.control.input_set);
  torch::NoGradGuard noGrad;
  const torch::Tensor exposure = batchExposure(val.noisy);
  const int64_t b = val.noisy.size(0), baseAux = 3 * (int64_t(set.buffers.size()) - 1);
  const torch::Tensor x =
      oidnBaseInput(torch::cat({val.noisy, val.aux.narrow(1, 0, baseAux)}, 1), set, exposure);
  const torch::Tensor base = trainer.controlled()->steered()->forward(x);
  const double baseLoss =
      torch::l1_loss(base, puEncode(val.target * exposure.view({b, 1, 1, 1}))).item<double>();
  return fmt::format("\"val_loss\": {:.6g}, \"base_val_loss\": {:.6g}", trainer.evaluate(val, 11),
                     baseLoss);
}

// dntrain defaults: the model's sampling defaults, validated against its schedule.
// The module holding a loaded model file's weights, whichever its kind.
const torch::nn::Module& weightsOf(const LoadedModel& loaded) {
  if (loaded.oidnControlled) return *loaded.oidnControlled;
  if (loaded.oidn) return *loaded.oidn;
  return *loaded.model;
}

int setDefaults(const Options& o) {
  LoadedModel loaded = loadModelFile(o.model);
  ModelInfo& info = loaded.info;
  if (!o.temporalTrust.empty()) {
    try {
      info.notes["temporal_trust"] = temporal::LearnedTrust::fromFile(o.temporalTrust).toText();
    } catch (const std::invalid_argument& e) {
      throw IoError(e.what());
    }
  }
  if (!o.respacing.empty()) info.respacing = o.respacing;
  if (o.defaultSkip >= 0) info.notes["default_skip"] = std::to_string(o.defaultSkip);
  if (o.defaultSpp > 0) info.notes["default_spp"] = std::to_string(o.defaultSpp);
  if (o.exposureTarget > 0) info.notes["exposure_target"] = fmt::format("{}", o.exposureTarget);
  if (!o.noiseReference.empty()) {
    const Denoiser denoiser(loaded);  // measures at the exposure target just set
    double sum = 0.0;
    for (const auto& path : o.noiseReference) {
      const double noise = denoiser.measureNoise(readFrame(path));
      fmt::print(stderr, "dntrain: {}: noise {:.4f}\n", path, noise);
      sum += noise;
    }
    info.notes["noise_reference"] = fmt::format("{:.4f}", sum / o.noiseReference.size());
  }
  stampProvenance(info, o);
  auto& skip = info.notes["default_skip"];
  if (skip.empty()) skip = "0";
  try {
    startStep(info.samplingSchedule(), std::stoll(skip));
  } catch (const std::exception& e) {
    throw cli::UsageError(std::string("bad sampling defaults: ") + e.what());
  }
  saveModelFile(o.out, info, weightsOf(loaded));
  auto spp = info.notes.find("default_spp");
  auto exposure = info.notes.find("exposure_target");
  auto noise = info.notes.find("noise_reference");
  fmt::print(stderr,
             "dntrain: {}: respacing {}, skip {}, tuned at {} spp, exposure target {}, noise "
             "reference {}\n",
             o.out, info.respacing, skip, spp == info.notes.end() ? "unknown" : spp->second,
             exposure == info.notes.end() ? "none" : exposure->second,
             noise == info.notes.end() ? "none" : noise->second);
  return cli::kExitOk;
}

// The dump folders of the animated scenes under --data, training or held out.
std::vector<std::string> trustDumps(const Options& o, bool heldOut) {
  std::vector<std::string> out;
  for (const std::string& root : cli::splitList(o.data)) {
    if (!fs::is_directory(root)) throw IoError(root + ": not a folder");
    for (const auto& scene : fs::directory_iterator(root)) {
      const std::string name = scene.path().filename().string();
      if (name.rfind("scene_", 0) != 0 || !scene.is_directory()) continue;
      const char last = name.back();
      if ((last == '4' || last == '9') != heldOut) continue;
      for (const char* dump : {"dump4", "dump16"})
        if (fs::is_directory(scene.path() / dump)) out.push_back((scene.path() / dump).string());
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

// The loss of the frames alone, the dumps' rules and `trust` on `set`.
std::string trustReport(const TrustSet& set, const temporal::LearnedTrust& trust) {
  const double alone = trustLoss(set, torch::zeros_like(set.rules));
  const double rules = trustLoss(set, set.rules);
  const double learned = trustLoss(set, learnedWeights(set, trust));
  return fmt::format("{} frames, {} pixels: loss alone {:.6g}, rules {:.6g}, learned {:.6g}",
                     set.frames, set.size(), alone, rules, learned);
}

// dntrain trust: the temporal filter's learned trust.
int fitTrustMode(const Options& o) {
  torch::set_num_threads(o.threads > 0 ? o.threads
                                       : static_cast<int>(std::thread::hardware_concurrency()));
  const std::vector<std::string> trainDirs = trustDumps(o, false), valDirs = trustDumps(o, true);
  if (trainDirs.empty()) throw IoError(o.data + ": no scene_*/dump4 or dump16 to fit on");
  const TrustSet train = loadTrustSet(trainDirs, 2), val = loadTrustSet(valDirs, 2);
  TrustFitOptions options;
  if (o.given.count("--steps")) options.steps = static_cast<int>(o.steps);
  if (o.given.count("--batch")) options.batch = static_cast<int>(o.batch);
  if (o.given.count("--lr")) options.learningRate = o.lr;
  options.seed = o.seed;
  fmt::print(stderr, "dntrain trust: {} dump folders, {} frames, {} pixels; {} held out\n",
             trainDirs.size(), train.frames, train.size(), val.frames);
  double recent = 0.0;
  const temporal::LearnedTrust trust = fitTrust(train, options, [&](int step, double loss) {
    recent += loss;
    if (step % 500 == 0)
      fmt::print(stderr, "dntrain trust: step {}: loss {:.6g}\n", step, recent / 500), recent = 0.0;
  });
  fmt::print(stderr, "dntrain trust: training: {}\n", trustReport(train, trust));
  if (val.size() > 0) fmt::print(stderr, "dntrain trust: held out: {}\n", trustReport(val, trust));
  writeAtomically(o.out, [&](std::ostream& out) { out << trust.toText() << "\n"; });
  fmt::print(stderr, "dntrain trust: wrote {}\n", o.out);
  return cli::kExitOk;
}

// dntrain prior: the base prior of a controlled model as a plain model file.
int extractPrior(const Options& o) {
  const LoadedModel loaded = loadModelFile(o.model);
  if (!loaded.info.has_control) throw IoError(o.model + ": has no Control Module; it is a prior");
  ModelInfo info = loaded.info;
  info.has_control = false;
  info.input_buffers.clear();
  info.notes["extracted_from"] = fs::path(o.model).filename().string();
  stampProvenance(info, o);
  saveModelFile(o.out, info, PriorDenoiser(loaded.prior()));
  fmt::print(stderr, "dntrain: {}: the prior of {}\n", o.out, o.model);
  return cli::kExitOk;
}

// dntrain rebase: a Control Module over the OIDN base, moved onto another
// import of the same base that holds more networks.
int rebaseControl(const Options& o) {
  const LoadedModel from = loadModelFile(o.model);
  if (!from.oidnControlled)
    throw IoError(o.model + ": has no Control Module over the OIDN base to move");
  const LoadedModel onto = loadModelFile(o.base);
  if (!onto.oidn || onto.info.has_control)
    throw IoError(o.base + ": is not an OIDN base (dntrain import-oidn makes one)");
  const std::string& steered = from.info.oidn.control.input_set;
  const auto& sets = onto.info.oidn.input_sets;
  if (onto.info.oidn.arch != from.info.oidn.arch ||
      std::find(sets.begin(), sets.end(), steered) == sets.end())
    throw IoError(o.base + ": has no " + oidnArchName(from.info.oidn.arch) + " '" + steered +
                  "' network for the Control Module of " + o.model);
  const auto ours = from.oidnControlled->steered()->named_parameters();
  for (const auto& p : onto.oidn->net(steered)->named_parameters())
    if (!torch::equal(p.value(), ours[p.key()]))
      throw IoError(o.base + ": its '" + steered +
                    "' network is not the one the Control Module of " + o.model +
                    " was trained over (" + p.key() + " differs)");

  ModelInfo info = from.info;
  info.oidn.input_sets = sets;
  for (const auto& set : sets)
    for (const char* key : {".weights", ".blob_offset", ".blob_sha256"})
      if (onto.info.notes.count(set + key)) info.notes[set + key] = onto.info.notes.at(set + key);
  info.notes["rebased_onto"] = fs::path(o.base).filename().string();
  stampProvenance(info, o);
  OidnControlled model(onto.oidn, info.oidn.control);
  {
    torch::NoGradGuard noGrad;
    const auto trained = from.oidnControlled->control()->named_parameters();
    for (auto& p : model->control()->named_parameters()) p.value().copy_(trained[p.key()]);
  }
  saveModelFile(o.out, info, *model);
  fmt::print(stderr, "dntrain: {}: the Control Module of {} over {} ({} networks)\n", o.out,
             o.model, o.base, sets.size());
  return cli::kExitOk;
}

// dntrain import-oidn: OIDN's pretrained networks as a model file.
int importOidnModel(const Options& o) {
  const std::string lib = o.lib.empty() ? findOidnLibrary() : o.lib;
  const OidnImport imported = importOidn(lib, oidnArchFromName(o.variant));
  saveModelFile(o.out, imported.info, *imported.base);
  const auto& notes = imported.info.notes;
  fmt::print(stderr, "dntrain: {}: OIDN {} ({}), {} network{}:\n", o.out,
             notes.at("source_version"), lib, imported.info.oidn.input_sets.size(),
             imported.info.oidn.input_sets.size() > 1 ? "s" : "");
  for (const auto& set : imported.info.oidn.input_sets)
    fmt::print(stderr, "  {:<19} {} at offset {}, sha256 {}\n", set, notes.at(set + ".weights"),
               notes.at(set + ".blob_offset"), notes.at(set + ".blob_sha256"));
  return cli::kExitOk;
}

int run(const Options& o) {
  if (o.mode == "defaults") return setDefaults(o);
  if (o.mode == "trust") return fitTrustMode(o);
  if (o.mode == "import-oidn") return importOidnModel(o);
  if (o.mode == "rebase") return rebaseControl(o);
  if (o.mode == "prior") return extractPrior(o);
  // Debian's LibTorch starts with one thread: use every core unless told otherwise.
  torch::set_num_threads(o.threads > 0 ? o.threads
                                       : static_cast<int>(std::thread::hardware_concurrency()));
  // Joins the other ranks first, so bad distributed settings fail before any
  // loading (and Ctrl-C while waiting for them simply ends the process).
  DistributedOptions dist;
  dist.world_size = o.worldSize;
  dist.rank = o.rank;
  dist.master_addr = o.masterAddr;
  dist.master_port = o.masterPort;
  auto averager = std::make_shared<GradientAverager>(dist);
  const bool isMain = averager->isMain();  // only rank 0 writes and prints
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);

  BuiltModel built = buildModel(o);
  const ModelInfo& info = built.info;
  TrainerOptions to;
  to.learning_rate = o.lr;
  to.halve_every = o.halveEvery;
  to.ema_decay = o.ema;
  to.seed = o.seed;
  to.diffusion.max_timestep = o.maxTimestep;
  to.diffusion.render_start = o.renderStart;
  Trainer trainer =
      built.controlled ? Trainer(built.controlled, info, to) : Trainer(built.model, info, to);
  if (o.resume && fs::exists(o.checkpoint)) {
    trainer.loadCheckpoint(o.checkpoint);
    if (isMain)
      fmt::print(stderr, "dntrain: resumed {} at step {}\n", o.checkpoint, trainer.stepCount());
  }
  if (o.worldSize > 1) trainer.setGradientAverager(averager);

  BatchSource source(o, trainer.info(), "train", trainer.stepCount());
  // A fixed validation batch: from the 'val' split when there is one.
  std::optional<TrainBatch> val;
  if (o.valEvery > 0 && isMain) {
    Options vo = o;
    vo.seed = 12345;
    vo.batch = std::min<int64_t>(o.batch, 4);
    const bool hasVal =
        !o.data.empty() && fs::is_directory(fs::path(cli::splitList(o.data).front()) / "val");
    val = BatchSource(vo, trainer.info(), hasVal ? "val" : "train", 0).batch(0);
  }

  std::ofstream log;
  if (isMain) log.open(o.log, std::ios::app);
  if (isMain && !log) throw IoError(o.log + ": cannot open the log for writing");
  const auto start = Clock::now();
  auto lastCheckpoint = start;
  const int64_t firstStep = trainer.stepCount();
  const int64_t globalBatch = o.batch * o.worldSize;
  if (isMain)
    fmt::print(
        stderr, "dntrain {}: {} trainable parameters, steps {} -> {}\n", o.mode,
        [&] {
          int64_t n = 0;
          for (const auto& p : trainer.trainableParameters()) n += p.numel();
          return n;
        }(),
        firstStep, o.steps);

  cli::Progress progress(stderr, cli::kTrainingLineSeconds);
  bool stop = false;  // agreed by all ranks, so they leave the loop together
  while (trainer.stepCount() < o.steps && !(stop = averager->any(stopRequested))) {
    TrainBatch batch = source.batch(trainer.stepCount());
    StepStats stats = trainer.step(batch);
    const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
    if (!isMain) continue;
    const double rate = (stats.step - firstStep) * globalBatch / elapsed;
    const double eta = (o.steps - stats.step) * globalBatch / std::max(rate, 1e-9);
    log << fmt::format(
        "{{\"step\": {}, \"loss\": {:.6g}, \"lr\": {:.3g}, \"samples_per_s\": {:.3f}, "
        "\"elapsed_s\": {:.1f}",
        stats.step, stats.loss, stats.learning_rate, rate, elapsed);
    if (val && (stats.step % o.valEvery == 0 || stats.step == o.steps))
      log << ", "
          << (built.controlled ? validateControlled(trainer, *val)
                               : validate(trainer, *val, tonemap::curveFromName(info.tonemap)));
    log << "}\n" << std::flush;
    progress.update(
        double(stats.step) / o.steps,
        fmt::format("dntrain {}: step {}/{}  loss {:.4f}  {:.1f} samples/s  elapsed {}  "
                    "ETA {}",
                    o.mode, stats.step, o.steps, stats.loss, rate, cli::formatDuration(elapsed),
                    cli::formatDuration(eta)));
    if (std::chrono::duration<double>(Clock::now() - lastCheckpoint).count() >
        60 * o.checkpointMinutes) {
      trainer.saveCheckpoint(o.checkpoint);
      lastCheckpoint = Clock::now();
    }
  }
  if (!isMain) return stop ? 130 : cli::kExitOk;
  progress.finish();
  trainer.saveCheckpoint(o.checkpoint);
  if (stop) {
    fmt::print(stderr,
               "dntrain: interrupted at step {}; checkpoint {} saved (continue with --resume)\n",
               trainer.stepCount(), o.checkpoint);
    return 130;
  }
  trainer.saveEmaModel(o.out);
  fmt::print(stderr, "dntrain: wrote {} after {} steps\n", o.out, trainer.stepCount());
  return cli::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  removeTemporaryFilesOnSignal("dntrain");  // training replaces it with a checkpoint handler
  try {
    return run(parseArgs(argc, argv));
  } catch (const std::exception& e) {
    fmt::print(stderr, "dntrain: {}\n", e.what());
  }
  return cli::kExitError;
}
