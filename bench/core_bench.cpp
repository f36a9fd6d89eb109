// Speed of the diffusion core on this machine: parameter counts, forward times of
// the base prior and the Control Module, training throughput and achieved FLOP/s
// (convolution and attention FLOPs counted analytically from the configs).
//
//   core_bench [--aux N] [--iters N] [--train-steps N] [--threads N] [--skip-large]
//              [--skip-forward] [--base-channels N] [--res-blocks N] [--mults 1,2,4]
//              [--attention 2|none] [--middle-attention 0|1] [--channels-last]
//              [--flush-denormal] [--profile TRACE.json]
#include <ATen/CPUGeneratorImpl.h>
#include <torch/csrc/autograd/profiler_legacy.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "dn/nn/control_module.h"
#include "dn/nn/unet.h"
#include "dn/train/trainer.h"

using namespace dn;

namespace {

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Median-free but warmed-up mean of `iters` runs.
double timeIt(int iters, const std::function<void()>& fn) {
  fn();
  auto start = Clock::now();
  for (int i = 0; i < iters; ++i) fn();
  return secondsSince(start) / iters;
}

// Multiply-adds counted as 2 FLOPs; `weights` collects conv weight element counts
// so the walk can be checked against the real network.
struct FlopCount {
  double flops = 0;
  int64_t conv_weights = 0;
  void conv(int64_t in, int64_t out, int64_t k, int64_t h, int64_t w) {
    flops += 2.0 * double(in) * out * k * k * h * w;
    conv_weights += in * out * k * k;
  }
  void attention(int64_t c, int64_t h, int64_t w) {
    conv(c, 3 * c, 1, h, w);
    conv(c, c, 1, h, w);
    const double n = double(h) * w;
    flops += 2.0 * 2.0 * n * n * c;  // QK^T and AV
  }
  void resBlock(int64_t in, int64_t out, int64_t h, int64_t w) {
    conv(in, out, 3, h, w);
    conv(out, out, 3, h, w);
    if (in != out) conv(in, out, 1, h, w);
  }
};

// The UNet's encoder + middle block at an input of h x w (mirrors UNetEncoder).
FlopCount encoderFlops(const UNetConfig& c, int64_t h, int64_t w,
                       std::vector<int64_t>* skip_sizes) {
  FlopCount count;
  count.conv(c.in_channels + c.cond_channels, c.base_channels, 3, h, w);
  int64_t ch = c.base_channels;
  auto skip = [&](int64_t channels, int64_t hh, int64_t ww) {
    if (skip_sizes) skip_sizes->insert(skip_sizes->end(), {channels, hh, ww});
  };
  skip(ch, h, w);
  for (int64_t level = 0; level < c.levels(); ++level) {
    const int64_t out = c.base_channels * c.channel_mults[level];
    for (int64_t i = 0; i < c.res_blocks; ++i) {
      count.resBlock(ch, out, h, w);
      if (c.hasAttention(level)) count.attention(out, h, w);
      ch = out;
      skip(ch, h, w);
    }
    if (level + 1 < c.levels()) {
      h /= 2, w /= 2;
      count.conv(ch, ch, 3, h, w);
      skip(ch, h, w);
    }
  }
  count.resBlock(ch, ch, h, w);
  if (c.middle_attention) count.attention(ch, h, w);
  count.resBlock(ch, ch, h, w);
  return count;
}

// The decoder and output layers (mirrors UNet's constructor).
FlopCount decoderFlops(const UNetConfig& c, int64_t h, int64_t w) {
  std::vector<int64_t> skips;
  encoderFlops(c, h, w, &skips);
  FlopCount count;
  int64_t ch = c.base_channels * c.channel_mults.back();
  h >>= (c.levels() - 1), w >>= (c.levels() - 1);
  for (int64_t level = c.levels() - 1; level >= 0; --level) {
    const int64_t out = c.base_channels * c.channel_mults[level];
    for (int64_t i = 0; i <= c.res_blocks; ++i) {
      const int64_t skip_channels = skips[skips.size() - 3];
      skips.resize(skips.size() - 3);
      count.resBlock(ch + skip_channels, out, h, w);
      if (c.hasAttention(level)) count.attention(out, h, w);
      ch = out;
      if (level > 0 && i == c.res_blocks) {
        h *= 2, w *= 2;
        count.conv(ch, ch, 3, h, w);
      }
    }
  }
  count.conv(ch, c.out_channels, 3, h, w);
  return count;
}

// Control Module beyond its encoder copy: hint convs and zero convs.
FlopCount controlExtraFlops(const UNetConfig& u, const ControlConfig& c, int64_t h, int64_t w) {
  FlopCount count;
  int64_t ch = c.aux_channels + c.radiance_channels;
  for (int64_t i = 0; i < c.hint_layers; ++i) {
    count.conv(ch, c.hint_channels, 3, h, w);
    ch = c.hint_channels;
  }
  count.conv(ch, u.base_channels, 3, h, w);
  std::vector<int64_t> skips;
  encoderFlops(u, h, w, &skips);
  for (size_t i = 0; i < skips.size(); i += 3)
    count.conv(skips[i], skips[i], 1, skips[i + 1], skips[i + 2]);
  const int64_t middle = u.base_channels * u.channel_mults.back();
  count.conv(middle, middle, 1, h >> (u.levels() - 1), w >> (u.levels() - 1));
  return count;
}

int64_t convWeightCount(const torch::nn::Module& module) {
  int64_t count = 0;
  for (const auto& p : module.parameters())
    if (p.dim() == 4) count += p.numel();
  return count;
}

double peakFlopsEstimate() {
  // AVX2: two 8-wide FMA units per core = 32 fp32 FLOPs per cycle.
  std::ifstream cpuinfo("/proc/cpuinfo");
  std::string line;
  double mhz = 0;
  while (std::getline(cpuinfo, line))
    if (line.rfind("cpu MHz", 0) == 0)
      mhz = std::max(mhz, std::atof(line.substr(line.find(':') + 1).c_str()));
  return 32.0 * mhz * 1e6 * torch::get_num_threads();
}

struct Args {
  int64_t aux = 36;
  int iters = 3;
  int train_steps = 10;
  int threads = 0;
  int64_t res_blocks = -1;
  int64_t base_channels = -1;
  std::string mults;      // e.g. "1,2,4"
  std::string attention;  // attention levels, e.g. "2" or "none"
  int middle_attention = -1;
  bool skip_large = false;
  bool skip_forward = false;
  bool channels_last = false;
  bool flush_denormal = false;
  std::string profile;  // chrome trace of the control training steps
};

// NHWC weights make oneDNN pick its blocked convolution kernels directly.
void toChannelsLast(torch::nn::Module& module) {
  torch::NoGradGuard no_grad;
  for (auto& p : module.parameters())
    if (p.dim() == 4) p.set_data(p.contiguous(torch::MemoryFormat::ChannelsLast));
}

std::vector<int64_t> parseList(const std::string& text) {
  std::vector<int64_t> values;
  if (text == "none") return values;
  size_t start = 0;
  while (start <= text.size()) {
    const size_t comma = text.find(',', start);
    values.push_back(std::atol(text.substr(start, comma - start).c_str()));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return values;
}

Args parseArgs(int argc, char** argv) {
  Args args;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto text = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "core_bench: %s needs a value\n", arg.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    auto next = [&]() -> long { return std::atol(text().c_str()); };
    if (arg == "--aux")
      args.aux = next();
    else if (arg == "--iters")
      args.iters = int(next());
    else if (arg == "--train-steps")
      args.train_steps = int(next());
    else if (arg == "--threads")
      args.threads = int(next());
    else if (arg == "--res-blocks")
      args.res_blocks = next();
    else if (arg == "--base-channels")
      args.base_channels = next();
    else if (arg == "--mults")
      args.mults = text();
    else if (arg == "--attention")
      args.attention = text();
    else if (arg == "--middle-attention")
      args.middle_attention = int(next());
    else if (arg == "--skip-large")
      args.skip_large = true;
    else if (arg == "--skip-forward")
      args.skip_forward = true;
    else if (arg == "--channels-last")
      args.channels_last = true;
    else if (arg == "--flush-denormal")
      args.flush_denormal = true;
    else if (arg == "--profile")
      args.profile = text();
    else {
      std::fprintf(stderr, "core_bench: unknown argument %s\n", arg.c_str());
      std::exit(2);
    }
  }
  return args;
}

TrainBatch randomBatch(int64_t batch, int64_t size, int64_t aux, torch::Generator& generator) {
  TrainBatch b;
  b.target = torch::rand({batch, 3, size, size}, generator, torch::kFloat);
  b.noisy = torch::rand({batch, 3, size, size}, generator, torch::kFloat);
  if (aux > 0) b.aux = torch::rand({batch, aux, size, size}, generator, torch::kFloat);
  return b;
}

void benchTraining(const char* label, ConditionalDenoiser& model, const ModelInfo& info,
                   int64_t aux, double train_flops_per_sample, int steps, double peak) {
  const int64_t batch = 8, crop = 64;
  auto generator = at::detail::createCPUGenerator(1);
  auto schedule = info.trainingSchedule();
  std::vector<torch::Tensor> trainable;
  for (auto& p : model.parameters())
    if (p.requires_grad()) trainable.push_back(p);
  torch::optim::AdamW optimizer(trainable, torch::optim::AdamWOptions(1e-4));
  model.train();
  double forward = 0, backward = 0, update = 0;
  for (int i = 0; i <= steps; ++i) {  // step 0 warms up
    auto data = randomBatch(batch, crop, aux, generator);
    auto t0 = Clock::now();
    optimizer.zero_grad();
    auto loss = diffusionLoss(model, schedule, info.prediction, data, generator);
    auto t1 = Clock::now();
    loss.backward();
    auto t2 = Clock::now();
    optimizer.step();
    auto t3 = Clock::now();
    if (i == 0) continue;
    forward += std::chrono::duration<double>(t1 - t0).count();
    backward += std::chrono::duration<double>(t2 - t1).count();
    update += std::chrono::duration<double>(t3 - t2).count();
  }
  const double per_step = (forward + backward + update) / steps;
  const double achieved = train_flops_per_sample * batch / per_step;
  std::printf(
      "train %-22s batch %ld at %ldx%ld: %.1f samples/s  (forward %.0f ms, backward %.0f ms, "
      "AdamW %.1f ms per step)  %.1f GFLOP/s = %.0f%% of fp32 peak\n",
      label, long(batch), long(crop), long(crop), batch / per_step, 1e3 * forward / steps,
      1e3 * backward / steps, 1e3 * update / steps, achieved / 1e9, 100.0 * achieved / peak);
}

}  // namespace

int main(int argc, char** argv) {
  const Args args = parseArgs(argc, argv);
  // This LibTorch build starts with one intra-op thread; use every core unless told.
  torch::set_num_threads(args.threads > 0 ? args.threads
                                          : int(std::max(1u, std::thread::hardware_concurrency())));
  torch::manual_seed(0);
  if (args.flush_denormal) at::globalContext().setFlushDenormal(true);
  ModelInfo info;
  if (args.res_blocks > 0) info.base.res_blocks = args.res_blocks;
  if (args.base_channels > 0) info.base.base_channels = args.base_channels;
  if (!args.mults.empty()) info.base.channel_mults = parseList(args.mults);
  if (!args.attention.empty()) info.base.attention_levels = parseList(args.attention);
  if (args.middle_attention >= 0) info.base.middle_attention = args.middle_attention != 0;
  info.control.aux_channels = args.aux;
  const auto& uc = info.base;
  const double peak = peakFlopsEstimate();
  std::printf("threads %d, fp32 peak estimate %.0f GFLOP/s (32 FLOP/cycle/core)\n",
              torch::get_num_threads(), peak / 1e9);
  std::printf("base UNet: channels %ld, mults", long(uc.base_channels));
  for (auto m : uc.channel_mults) std::printf(" %ld", long(m));
  std::printf(", %ld res blocks/level, attention at level(s)", long(uc.res_blocks));
  for (auto l : uc.attention_levels) std::printf(" %ld", long(l));
  std::printf(" + middle; control: %ld aux channels\n", long(args.aux));

  auto base = std::make_shared<UNet>(uc);
  auto controlled = std::make_shared<ControlledDenoiser>(base, info.control);
  auto control = controlled->control();
  if (args.channels_last) toChannelsLast(*controlled);
  std::printf("parameters: base %.3f M, control %.3f M (trainable)\n", parameterCount(*base) / 1e6,
              parameterCount(*control) / 1e6);

  // The analytic walk must see exactly the network's convolutions.
  const int64_t walked_base =
      encoderFlops(uc, 64, 64, nullptr).conv_weights + decoderFlops(uc, 64, 64).conv_weights;
  const int64_t walked_control = encoderFlops(uc, 64, 64, nullptr).conv_weights +
                                 controlExtraFlops(uc, info.control, 64, 64).conv_weights;
  if (walked_base != convWeightCount(*base) || walked_control != convWeightCount(*control)) {
    std::fprintf(stderr,
                 "core_bench: FLOP walk disagrees with the network (%ld vs %ld, %ld vs %ld)\n",
                 long(walked_base), long(convWeightCount(*base)), long(walked_control),
                 long(convWeightCount(*control)));
    return 1;
  }

  // A single 32->32 3x3 conv on 512x512 as a reference for achievable throughput.
  {
    torch::NoGradGuard no_grad;
    auto conv = torch::nn::Conv2d(torch::nn::Conv2dOptions(32, 32, 3).padding(1));
    auto x = torch::randn({1, 32, 512, 512});
    const double s = timeIt(args.iters, [&] { conv->forward(x); });
    const double flops = 2.0 * 32 * 32 * 9 * 512 * 512;
    std::printf("reference conv 32->32 3x3 at 512x512: %.1f ms, %.1f GFLOP/s\n", 1e3 * s,
                flops / s / 1e9);
  }

  controlled->eval();
  std::vector<int64_t> sizes = {128, 256};
  if (args.skip_large) sizes = {128};
  if (args.skip_forward) sizes.clear();
  for (int64_t size : sizes) {
    torch::NoGradGuard no_grad;
    auto generator = at::detail::createCPUGenerator(2);
    auto z = torch::randn({1, 3, size, size}, generator, torch::kFloat);
    auto cond = torch::randn({1, 3, size, size}, generator, torch::kFloat);
    auto aux = torch::rand({1, args.aux, size, size}, generator, torch::kFloat);
    auto t = torch::tensor({500.0f});
    const double base_flops =
        encoderFlops(uc, size, size, nullptr).flops + decoderFlops(uc, size, size).flops;
    const double control_flops = encoderFlops(uc, size, size, nullptr).flops +
                                 controlExtraFlops(uc, info.control, size, size).flops;
    const double base_s = timeIt(args.iters, [&] { base->predict(z, t, cond); });
    const double control_s = timeIt(args.iters, [&] { control->forward(z, t, cond, aux); });
    const double total_s = timeIt(args.iters, [&] { controlled->forward(z, t, cond, aux); });
    std::printf(
        "forward %ldx%ld: base %.0f ms (%.2f GFLOP, %.1f GFLOP/s), control %.0f ms (%.2f GFLOP, "
        "%.1f GFLOP/s), base+control %.0f ms; 27 steps %.1f s\n",
        long(size), long(size), 1e3 * base_s, base_flops / 1e9, base_flops / base_s / 1e9,
        1e3 * control_s, control_flops / 1e9, control_flops / control_s / 1e9, 1e3 * total_s,
        27 * total_s);
  }

  // Training FLOPs per 64x64 sample: backward costs ~2x forward for trained layers,
  // ~1x for frozen layers the gradient passes through (the base decoder only).
  const double enc = encoderFlops(uc, 64, 64, nullptr).flops, dec = decoderFlops(uc, 64, 64).flops;
  const double extra = controlExtraFlops(uc, info.control, 64, 64).flops;
  const double control_train = (enc + dec) + (enc + extra) * 3 + dec;
  const double base_train = 3 * (enc + dec);
  {
    std::unique_ptr<torch::autograd::profiler::RecordProfile> profiler;
    if (!args.profile.empty())
      profiler = std::make_unique<torch::autograd::profiler::RecordProfile>(args.profile);
    benchTraining("control (frozen base)", *controlled, info, args.aux, control_train,
                  args.train_steps, peak);
  }
  auto base_only = std::make_shared<PriorDenoiser>(std::make_shared<UNet>(uc));
  if (args.channels_last) toChannelsLast(*base_only);
  ModelInfo base_info = info;
  base_info.has_control = false;
  benchTraining("base prior", *base_only, base_info, 0, base_train, args.train_steps, peak);
  return 0;
}
