// dncleanse: the Noise2Noise ground-truth cleanser (and the Isik baseline denoiser).
//   dncleanse train --data DIR --out cleanser.pt [options]
//   dncleanse apply --model cleanser.pt --data DIR [--force]
//   dncleanse IN.exr -o OUT.exr --model M
#include <fmt/format.h>
#include <torch/version.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <set>

#include <unistd.h>

#include "common/app.h"
#include "common/cli.h"
#include "common/finite.h"
#include "common/progress.h"
#include "common/version.h"
#include "dn/data/dataset.h"
#include "dn/infer/denoiser.h"
#include "dn/io/buffer_io.h"
#include "dn/io/output_files.h"
#include "dn/nn/kernel_net.h"
#include "dn/nn/model_file.h"
#include "dn/nn/model_inputs.h"
#include "dn/train/kernel_trainer.h"

namespace fs = std::filesystem;
using namespace dn;
using Clock = std::chrono::steady_clock;

namespace {

const char* kUsage = R"(usage: dncleanse train --data DIR --out MODEL [options]
       dncleanse apply --model MODEL --data DIR [--force] [--source a|b|mean] [--split NAME]
       dncleanse IN.exr -o OUT.exr --model MODEL [--layer NAME] [--rgb-only]
       dncleanse --version

A kernel-predicting network (Isik et al. 2021, no temporal terms) trained with
SMAPE. --task cleanse (default) learns ground truth -> the other ground truth
(Noise2Noise), and `apply` writes gt_clean.exr beside every frame of a data set;
--task denoise learns low-spp input -> clean target (the "Isik" baseline).
`apply` also takes a denoiser model (models/oidn.dnm, the pretrained base): it
denoises the ground truth with the frame's own albedo and normal.

train options:
  --data DIR             data set (docs/dataset.md); frames of --train-split
  --out MODEL            model file (EMA weights), written atomically
  --steps N              total steps, >= 1 (default 20000)
  --batch B              samples per step, 1-1024 (default 8)
  --crop C               square crop size, 8-4096 (default 64)
  --lr X                 Adam learning rate, in (0, 1] (default 1e-3)
  --halve-every N        halve the learning rate every N steps (default 0: never)
  --seed S               data order and initial weights, >= 0 (default 1)
  --task cleanse|denoise (default cleanse)
  --spp LIST             denoise input sample counts (default 4,16,32)
  --buffers LIST         aux buffers (default: the standard Cycles set, see docs)
  --widths LIST          UNet widths per level, each 1-1024 (default 24,32,48)
  --dilations LIST       one kernel iteration per dilation, each 1-64 (default 1,2,4)
  --feature-dims N       affinity features per iteration, 1-256 (default 8)
  --demodulate on|off    filter radiance / albedo, then multiply back (default on)
  --val-every N          validation SMAPE every N steps (default 0: never)
  --val-samples N        validation crops, 1-100000 (default 32)
  --train-split NAME     (default train)    --val-split NAME  (default val)
  --log FILE             JSON lines log (default MODEL.log.jsonl)
  --checkpoint FILE      (default MODEL.ckpt), written every --checkpoint-minutes
  --checkpoint-minutes M (default 5) and on SIGINT/SIGTERM
  --resume               continue the run in --checkpoint (same data order,
                         optimizer state and step); --steps may be raised
  --threads N            compute threads, 1-1024 (default 2)
apply options:
  --force                recompute frames that already have gt_clean.exr
  --source a|b|mean      which ground truth to cleanse (default a; mean: the
                         mean of both, denoiser models only)
  --split NAME           only this split's frames (default: every split)
single-file options:
  -o OUT                 output file: the input's layers plus the result layer
  --layer NAME           result layer (default Cleansed or Denoised, by the model's task)
  --view-layer NAME      the view layer of a multilayer file with several
  --rgb-only             write a plain RGB file instead
exit codes: 0 ok, 1 bad input or arguments, 130/143 training stopped by SIGINT/SIGTERM
            (checkpoint written; continue with --resume)
)";

volatile std::sig_atomic_t g_stop_signal = 0;
extern "C" void onStopSignal(int signal) { g_stop_signal = signal; }

std::vector<int64_t> toInt64s(const std::string& option, const std::string& text, int lo, int hi) {
  const auto list = cli::intList(option, text, lo, hi);
  return {list.begin(), list.end()};
}

bool onOff(const std::string& option, const std::string& value) {
  if (value == "on") return true;
  if (value == "off") return false;
  throw cli::UsageError(option + " wants on or off, got '" + value + "'");
}

std::string joined(const std::vector<std::string>& items) {
  std::string out;
  for (size_t i = 0; i < items.size(); ++i) out += (i ? "," : "") + items[i];
  return out;
}

// A JSON string literal (paths may hold quotes or backslashes).
std::string jsonString(const std::string& text) {
  std::string out = "\"";
  for (const char c : text) {
    if (c == '"' || c == '\\') out += '\\';
    if (static_cast<unsigned char>(c) < 0x20)
      out += fmt::format("\\u{:04x}", int(c));
    else
      out += c;
  }
  return out + "\"";
}

// ---------------------------------------------------------------- train

struct TrainOptions {
  std::string data, out, log, checkpoint;
  int steps = 20000, batch = 8, crop = 64, halve_every = 0, threads = 2;
  int val_every = 0, val_samples = 32;
  double lr = 1e-3, checkpoint_minutes = 5;
  std::string seed = "1", task = "cleanse", spp = "4,16,32";
  std::string train_split = "train", val_split = "val";
  bool resume = false;
  std::string command;  // recorded in the model file
  KernelNetConfig net;
  std::set<std::string> given;  // options set on the command line
};

// The settings that define a run: stored in checkpoints, checked on --resume.
std::map<std::string, std::string> runSettings(const TrainOptions& o) {
  return {{"data", o.data},
          {"batch", std::to_string(o.batch)},
          {"crop", std::to_string(o.crop)},
          {"lr", fmt::format("{}", o.lr)},
          {"halve_every", std::to_string(o.halve_every)},
          {"seed", o.seed},
          {"task", o.task},
          {"spp", o.spp},
          {"train_split", o.train_split}};
}

// The command-line option behind each run setting.
const std::map<std::string, std::string> kSettingOption = {{"data", "--data"},
                                                           {"batch", "--batch"},
                                                           {"crop", "--crop"},
                                                           {"lr", "--lr"},
                                                           {"halve_every", "--halve-every"},
                                                           {"seed", "--seed"},
                                                           {"task", "--task"},
                                                           {"spp", "--spp"},
                                                           {"train_split", "--train-split"}};

TrainOptions parseTrain(cli::Args& args) {
  TrainOptions o;
  o.net.input_buffers = defaultAuxBuffers();
  o.net.demodulate = true;
  while (!args.done()) {
    const std::string arg = args.peek();
    auto take = [&](const char* name) {
      if (!args.flag(name)) return false;
      o.given.insert(name);
      return true;
    };
    if (take("--data"))
      o.data = args.value("--data");
    else if (take("--out"))
      o.out = args.value("--out");
    else if (take("--log"))
      o.log = args.value("--log");
    else if (take("--checkpoint"))
      o.checkpoint = args.value("--checkpoint");
    else if (take("--steps"))
      o.steps = args.intValue("--steps", 1, INT32_MAX);
    else if (take("--batch"))
      o.batch = args.intValue("--batch", 1, 1024);
    else if (take("--crop"))
      o.crop = args.intValue("--crop", 8, 4096);
    else if (take("--lr"))
      o.lr = args.doubleValue("--lr", 1e-12, 1.0);
    else if (take("--halve-every"))
      o.halve_every = args.intValue("--halve-every", 0, INT32_MAX);
    else if (take("--threads"))
      o.threads = args.intValue("--threads", 1, 1024);
    else if (take("--seed"))
      o.seed = std::to_string(args.intValue("--seed", 0, INT32_MAX));
    else if (take("--task"))
      o.task = args.value("--task");
    else if (take("--spp")) {
      o.spp = args.value("--spp");
      cli::intList("--spp", o.spp, 1, 1 << 24);
    } else if (take("--val-every"))
      o.val_every = args.intValue("--val-every", 0, INT32_MAX);
    else if (take("--val-samples"))
      o.val_samples = args.intValue("--val-samples", 1, 100000);
    else if (take("--train-split"))
      o.train_split = args.value("--train-split");
    else if (take("--val-split"))
      o.val_split = args.value("--val-split");
    else if (take("--checkpoint-minutes"))
      o.checkpoint_minutes = args.doubleValue("--checkpoint-minutes", 0.0, 1e6);
    else if (take("--resume"))
      o.resume = true;
    else if (take("--buffers"))
      o.net.input_buffers = cli::splitList(args.value("--buffers"));
    else if (take("--widths"))
      o.net.widths = toInt64s("--widths", args.value("--widths"), 1, 1024);
    else if (take("--dilations"))
      o.net.dilations = toInt64s("--dilations", args.value("--dilations"), 1, 64);
    else if (take("--feature-dims"))
      o.net.feature_dims = args.intValue("--feature-dims", 1, 256);
    else if (take("--demodulate"))
      o.net.demodulate = onOff("--demodulate", args.value("--demodulate"));
    else
      throw cli::UsageError("train: unknown argument '" + arg + "'");
  }
  if (o.out.empty()) throw cli::UsageError("train needs --out MODEL");
  if (o.data.empty() && !o.resume) throw cli::UsageError("train needs --data DIR");
  if (o.log.empty()) o.log = o.out + ".log.jsonl";
  if (o.checkpoint.empty()) o.checkpoint = o.out + ".ckpt";
  // The model, its log and its checkpoint are three different files; a resumed
  // run reads the checkpoint it then rewrites, which is the point of it.
  cli::checkFiles({}, {{o.out, "--out"}, {o.log, "--log"}, {o.checkpoint, "--checkpoint"}});
  if (!o.resume && fs::exists(o.checkpoint))
    throw cli::UsageError(o.checkpoint + " exists: continue that run with --resume, or delete it");
  if (!(o.checkpoint_minutes > 0)) throw cli::UsageError("--checkpoint-minutes must be above 0");
  try {
    kernelTaskFromName(o.task);
    o.net.validate();
  } catch (const std::invalid_argument& error) {
    throw cli::UsageError(std::string("train: ") + error.what());
  }
  return o;
}

// --resume: the run's settings and network come from the checkpoint; options
// given again must agree with it.
KernelModelInfo adoptCheckpoint(TrainOptions& o) {
  if (!fs::exists(o.checkpoint))
    throw IoError(o.checkpoint + ": no checkpoint to resume (run without --resume first)");
  auto header = readKernelCheckpointHeader(o.checkpoint);
  const auto mine = runSettings(o);
  for (const auto& [key, option] : kSettingOption) {
    auto stored = header.run_state.find(key);
    if (stored == header.run_state.end())
      throw ModelError(o.checkpoint + ": checkpoint lacks the run setting '" + key + "'");
    if (o.given.count(option) && mine.at(key) != stored->second)
      throw cli::UsageError(option + " " + mine.at(key) + " differs from the checkpoint's " +
                            stored->second + " (" + o.checkpoint + ")");
  }
  const auto& s = header.run_state;
  for (const char* key : {"loader_position", "seconds"})
    if (!s.count(key)) throw ModelError(o.checkpoint + ": checkpoint lacks '" + key + "'");
  o.data = s.at("data");
  o.batch = std::stoi(s.at("batch"));
  o.crop = std::stoi(s.at("crop"));
  o.lr = std::stod(s.at("lr"));
  o.halve_every = std::stoi(s.at("halve_every"));
  o.seed = s.at("seed");
  o.task = s.at("task");
  o.spp = s.at("spp");
  o.train_split = s.at("train_split");
  for (const char* option :
       {"--buffers", "--widths", "--dilations", "--feature-dims", "--demodulate"})
    if (o.given.count(option))
      throw cli::UsageError(std::string(option) + " cannot change when resuming");
  return header.info;
}

data::SampleOptions sampleOptions(const TrainOptions& o, const KernelNetConfig& net) {
  data::SampleOptions s;
  s.task = o.task == "cleanse" ? data::Task::Cleanse : data::Task::Denoise;
  s.spp.clear();
  for (const auto& item : cli::splitList(o.spp)) s.spp.push_back(cli::Args::toInt("--spp", item));
  if (s.spp.empty()) throw cli::UsageError("--spp needs a list");
  s.aux = net.input_buffers;
  s.crop = o.crop;
  return s;
}

struct Tensors {
  torch::Tensor radiance, aux, target;
};

Tensors toTensors(data::Batch& batch) {
  const auto shape = [&](int channels) {
    return std::vector<int64_t>{batch.size, channels, batch.height, batch.width};
  };
  return {torch::from_blob(batch.color.data(), shape(3)).clone(),
          torch::from_blob(batch.aux.data(), shape(batch.auxChannels)).clone(),
          torch::from_blob(batch.target.data(), shape(3)).clone()};
}

// A fixed validation set, decoded once: the same crops every time.
std::vector<Tensors> validationSet(const TrainOptions& o, const KernelNetConfig& net) {
  auto s = sampleOptions(o, net);
  s.augment = false;
  data::LoaderOptions options;
  options.batchSize = std::min(o.batch, o.val_samples);
  options.threads = 1;
  options.seed = 0x5eed;
  data::Loader loader(data::scanDataset(o.data, o.val_split), s, options);
  std::vector<Tensors> batches;
  for (int n = 0; n < o.val_samples; n += options.batchSize) {
    auto batch = loader.next();
    batches.push_back(toTensors(batch));
  }
  return batches;
}

class JsonLog {
 public:
  explicit JsonLog(const std::string& path) : path_(path), out_(path, std::ios::app) {
    if (!out_) throw IoError(path + ": cannot open the log for appending");
  }
  void write(const std::string& line) {
    out_ << line << "\n";
    out_.flush();
    if (!out_) throw IoError(path_ + ": cannot write the log (disk full?)");
  }

 private:
  std::string path_;
  std::ofstream out_;
};

int runTrain(cli::Args& args, int argc, char** argv) {
  TrainOptions o = parseTrain(args);
  o.command = cli::commandLine(argc, argv);
  torch::set_num_threads(o.threads);
  KernelModelInfo info;
  info.net = o.net;
  if (o.resume) info = adoptCheckpoint(o);
  info.task = kernelTaskFromName(o.task);
  torch::manual_seed(std::stoull(o.seed));
  KernelTrainer trainer(KernelNet(info.net), info,
                        KernelTrainerOptions{o.lr, o.halve_every, 0.999, 1.0, 1e-2});
  uint64_t position = 0;
  double seconds_before = 0;
  if (o.resume) {
    const auto state = trainer.loadCheckpoint(o.checkpoint);
    position = std::stoull(state.at("loader_position"));
    seconds_before = std::stod(state.at("seconds"));
  }
  trainer.info().notes = {
      {"software", fmt::format("dncleanse {} ({})", DN_PROJECT_VERSION, DN_GIT_DESCRIBE)},
      {"command", o.command},
      {"data", o.data},
      {"task", o.task},
      {"batch", std::to_string(o.batch)},
      {"crop", std::to_string(o.crop)},
      {"spp", o.spp}};

  data::LoaderOptions loader_options;
  loader_options.batchSize = o.batch;
  loader_options.threads = 1;
  loader_options.seed = std::stoull(o.seed);
  data::Loader loader(data::scanDataset(o.data, o.train_split), sampleOptions(o, info.net),
                      loader_options, position);
  std::vector<Tensors> validation;
  if (o.val_every > 0) validation = validationSet(o, info.net);
  // The loss of passing the input through unchanged: a cleanser that does not
  // beat it has learned nothing (see docs/dncleanse.md).
  const auto identityLoss = [](const Tensors& t) {
    return kernelNetLoss(t.radiance, t.target, 1e-2).item<double>();
  };
  double identity_val = 0;
  for (const auto& v : validation) identity_val += identityLoss(v) / double(validation.size());
  JsonLog log(o.log);
  if (trainer.stepCount() == 0)
    log.write(fmt::format(
        R"({{"event":"start","task":"{}","data":{},"batch":{},"crop":{},"buffers":"{}"}})", o.task,
        jsonString(o.data), o.batch, o.crop, joined(info.net.input_buffers)));
  else
    log.write(fmt::format(R"({{"event":"resume","step":{}}})", trainer.stepCount()));

  std::signal(SIGINT, onStopSignal);
  std::signal(SIGTERM, onStopSignal);
  const auto start = Clock::now();
  auto last_checkpoint = start;
  cli::Progress progress(stderr, cli::kTrainingLineSeconds);
  double window_loss = 0, window_identity = 0, last_val = -1;
  int window_steps = 0;
  const int64_t first_step = trainer.stepCount();
  auto elapsed = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };
  auto save = [&] {
    trainer.saveCheckpoint(o.checkpoint, [&] {
      auto state = runSettings(o);
      state["loader_position"] = std::to_string(loader.position());
      state["seconds"] = fmt::format("{:.1f}", seconds_before + elapsed());
      return state;
    }());
    trainer.info().notes["steps"] = std::to_string(trainer.stepCount());
    trainer.saveModel(o.out);
    log.write(fmt::format(R"({{"event":"checkpoint","step":{},"path":{}}})", trainer.stepCount(),
                          jsonString(o.checkpoint)));
    last_checkpoint = Clock::now();
  };

  while (trainer.stepCount() < o.steps && !g_stop_signal) {
    auto batch = loader.next();
    const auto t = toTensors(batch);
    window_loss += trainer.step(t.radiance, t.aux, t.target);
    window_identity += identityLoss(t);
    ++window_steps;
    const int64_t step = trainer.stepCount();
    const double rate = double(step - first_step) * o.batch / std::max(elapsed(), 1e-9);
    if (window_steps == 10 || step == o.steps) {
      log.write(fmt::format(
          R"({{"event":"train","step":{},"loss":{:.6f},"identity_loss":{:.6f},"lr":{:g},"samples_per_s":{:.2f},"seconds":{:.1f}}})",
          step, window_loss / window_steps, window_identity / window_steps,
          trainer.currentLearningRate(), rate, seconds_before + elapsed()));
    }
    if (o.val_every > 0 && (step % o.val_every == 0 || step == o.steps)) {
      double sum = 0;
      for (const auto& v : validation) sum += trainer.evaluate(v.radiance, v.aux, v.target);
      last_val = sum / validation.size();
      log.write(fmt::format(
          R"({{"event":"validation","step":{},"smape":{:.6f},"identity_smape":{:.6f}}})", step,
          last_val, identity_val));
    }
    const auto now = Clock::now();
    const double eta = (o.steps - step) * o.batch / std::max(rate, 1e-9);
    const std::string val =
        last_val >= 0 ? fmt::format("  val {:.4f} (identity {:.4f})", last_val, identity_val) : "";
    progress.update(
        double(step) / o.steps,
        fmt::format("step {}/{}  loss {:.4f}{}  {:.1f} samples/s  elapsed {}  eta {}", step,
                    o.steps, window_loss / window_steps, val, rate,
                    cli::formatDuration(seconds_before + elapsed()), cli::formatDuration(eta)),
        now);
    if (window_steps == 10) window_loss = 0, window_identity = 0, window_steps = 0;
    if (now - last_checkpoint > std::chrono::duration<double>(o.checkpoint_minutes * 60)) save();
  }
  save();
  progress.finish();
  if (g_stop_signal) {
    std::fprintf(stderr,
                 "dncleanse: stopped at step %lld; checkpoint %s (continue with --resume)\n",
                 (long long)trainer.stepCount(), o.checkpoint.c_str());
    log.write(fmt::format(R"({{"event":"stopped","step":{},"signal":{}}})", trainer.stepCount(),
                          int(g_stop_signal)));
    return 128 + g_stop_signal;
  }
  log.write(fmt::format(R"({{"event":"done","step":{}}})", trainer.stepCount()));
  return cli::kExitOk;
}

// ---------------------------------------------------------------- apply

// Written as float: overflow (a 3.4e38 pixel through the kernels) becomes the
// largest float rather than Inf.
Image finiteResult(Image result, const std::string& name) {
  if (const std::size_t n = cli::clampToFinite(result))
    std::fprintf(stderr, "dncleanse: %s: %zu values beyond the float range clamped\n", name.c_str(),
                 n);
  return result;
}

// Cleanses one frame's ground truth with a kernel model (the Noise2Noise cleanser).
Image cleanseWithKernelNet(LoadedKernelModel& model, const fs::path& dir,
                           const std::string& source) {
  ReadOptions read;
  read.only = requiredBuffers(model.info.net);
  return runKernelNet(model.net, readFrame((dir / ("gt_" + source + ".exr")).string(), read));
}

// Cleanses with a denoiser model (the pretrained base) given the ground truth's
// own buffers; `mean` averages every buffer of both ground truths first, so
// that the colour and the light passes the base splits it by stay consistent.
Image cleanseWithDenoiser(const Denoiser& denoiser, const fs::path& dir,
                          const std::string& source) {
  FrameBuffers frame = readFrame((dir / (source == "b" ? "gt_b.exr" : "gt_a.exr")).string());
  if (source == "mean") {
    const std::string other = (dir / "gt_b.exr").string();
    const FrameBuffers second = readFrame(other);
    for (auto& [name, a] : frame.buffers) {
      if (!second.has(name)) throw IoError(other + ": has no " + name + " buffer, gt_a.exr has");
      const Image& b = second.get(name);
      if (a.width != b.width || a.height != b.height || a.channels != b.channels)
        throw IoError(other + ": " + name + " is not the size of gt_a.exr's");
      for (size_t i = 0; i < a.pixels.size(); ++i) a.pixels[i] = 0.5f * (a.pixels[i] + b.pixels[i]);
    }
  }
  DenoiseOptions options;
  options.control = ControlUse::Never;
  return denoiser.denoise(frame, options).color;
}

int runApply(cli::Args& args, int argc, char** argv) {
  std::string model_path, data_dir, source = "a", split;
  bool force = false;
  int threads = 2;
  while (!args.done()) {
    if (args.flag("--model"))
      model_path = args.value("--model");
    else if (args.flag("--data"))
      data_dir = args.value("--data");
    else if (args.flag("--force"))
      force = true;
    else if (args.flag("--source"))
      source = args.value("--source");
    else if (args.flag("--split"))
      split = args.value("--split");
    else if (args.flag("--threads"))
      threads = args.intValue("--threads", 1, 1024);
    else
      throw cli::UsageError("apply: unknown argument '" + args.peek() + "'");
  }
  if (model_path.empty() || data_dir.empty())
    throw cli::UsageError("apply needs --model and --data");
  if (source != "a" && source != "b" && source != "mean")
    throw cli::UsageError("--source must be a, b or mean");
  cli::checkReadable(model_path);
  torch::set_num_threads(threads);
  std::function<Image(const fs::path&)> cleanse;
  if (archiveKind(model_path) == "model") {
    auto denoiser = std::make_shared<Denoiser>(Denoiser::fromFile(model_path));
    cleanse = [denoiser, source](const fs::path& dir) {
      return cleanseWithDenoiser(*denoiser, dir, source);
    };
  } else {
    if (source == "mean") throw cli::UsageError("--source mean needs a denoiser model");
    auto model = std::make_shared<LoadedKernelModel>(loadKernelModel(model_path));
    if (model->info.task != KernelTask::Cleanse)
      throw ModelError(model_path + ": a " + kernelTaskName(model->info.task) +
                       " model; apply --data needs a cleanse model");
    cleanse = [model, source](const fs::path& dir) {
      return cleanseWithKernelNet(*model, dir, source);
    };
  }
  cli::setToolProvenance("dncleanse", argc, argv, model_path);
  const auto frames = data::scanDataset(data_dir, split);
  int written = 0, skipped = 0;
  const auto start = Clock::now();
  cli::Progress progress(stderr);
  for (size_t i = 0; i < frames.size(); ++i) {
    const fs::path dir(frames[i].dir);
    const auto out = (dir / "gt_clean.exr").string();
    if (!force && fs::exists(out)) {
      ++skipped;
      continue;
    }
    writeImage(out, finiteResult(cleanse(dir), out), false, {"R", "G", "B"});
    ++written;
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    progress.update(double(i + 1) / frames.size(), fmt::format("frame {}/{}  {:.2f} s/frame", i + 1,
                                                               frames.size(), seconds / written));
  }
  progress.finish();
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  std::fprintf(stderr, "dncleanse: wrote %d gt_clean.exr, skipped %d existing (%s)\n", written,
               skipped, cli::formatDuration(seconds).c_str());
  return cli::kExitOk;
}

// ---------------------------------------------------------------- one file

int runFile(cli::Args& args, int argc, char** argv) {
  std::string input, output, model_path, layer, viewLayer;
  bool rgb = false;
  int threads = 2;
  while (!args.done()) {
    if (args.flag("-o", "--output"))
      output = args.value("-o");
    else if (args.flag("--model"))
      model_path = args.value("--model");
    else if (args.flag("--layer")) {
      layer = args.value("--layer");
      if (layer.empty() || layer.find_first_of(". \t\n") != std::string::npos)
        throw cli::UsageError("--layer needs a name without dots or spaces, got '" + layer + "'");
    } else if (args.flag("--view-layer"))
      viewLayer = args.value("--view-layer");
    else if (args.flag("--rgb-only"))
      rgb = true;
    else if (args.flag("--threads"))
      threads = args.intValue("--threads", 1, 1024);
    else if (args.peek().rfind("-", 0) == 0 && args.peek() != "-")
      throw cli::UsageError("unknown option '" + args.peek() + "'");
    else if (input.empty())
      input = args.positional();
    else
      throw cli::UsageError("one input file only ('" + args.peek() + "')");
  }
  if (input.empty() || output.empty() || model_path.empty())
    throw cli::UsageError("usage: dncleanse IN.exr -o OUT.exr --model MODEL (see --help)");
  cli::checkFiles({input, model_path}, {{output, input}});
  torch::set_num_threads(threads);
  auto model = loadKernelModel(model_path);
  ReadOptions read;
  read.only = requiredBuffers(model.info.net);
  read.viewLayer = viewLayer;
  const auto frame = readFrame(input, read);
  WriteOptions write = writeOptionsFor(frame);  // its data window and alpha
  write.half = false;
  write.rgbOnly = rgb;
  write.layer = !layer.empty()
                    ? layer
                    : layerPrefixOf(frame) +
                          (model.info.task == KernelTask::Cleanse ? "Cleansed" : "Denoised");
  cli::setToolProvenance("dncleanse", argc, argv, model_path);
  writeResult(input, output, finiteResult(runKernelNet(model.net, frame), input), write);
  return cli::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  // Training replaces this with a handler that saves a checkpoint.
  removeTemporaryFilesOnSignal("dncleanse");
  try {
    cli::Args args(argc, argv);
    if (args.done()) throw cli::UsageError("no arguments (see --help)");
    if (args.flag("-h", "--help")) {
      std::fputs(kUsage, stdout);
      return cli::kExitOk;
    }
    if (args.flag("--version")) {
      auto components = cli::commonComponents();
      components.emplace_back("LibTorch", TORCH_VERSION);
      std::fputs(cli::versionText("dncleanse", components).c_str(), stdout);
      return cli::kExitOk;
    }
    if (args.flag("train")) return runTrain(args, argc, argv);
    if (args.flag("apply")) return runApply(args, argc, argv);
    return runFile(args, argc, argv);
  } catch (const cli::UsageError& error) {
    std::fprintf(stderr, "dncleanse: %s\n", error.what());
  } catch (const IoError& error) {
    std::fprintf(stderr, "dncleanse: %s\n", error.what());
  } catch (const ModelError& error) {
    std::fprintf(stderr, "dncleanse: %s\n", error.what());
  } catch (const std::exception& error) {
    std::string what = error.what();
    std::fprintf(stderr, "dncleanse: %s\n", what.substr(0, what.find('\n')).c_str());
  }
  return cli::kExitError;
}
