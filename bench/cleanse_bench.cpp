// Kernel-net (cleanser / Isik baseline) speed: parameters, training samples/s
// on random crops, and inference seconds per megapixel, split into the
// feature UNet and the kernel filtering.
//   BUILD/bin/cleanse_bench [--threads N] [--steps N] [--batch B] [--crop C] [--widths 24,32,48]
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "dn/nn/kernel_net.h"
#include "dn/nn/model_inputs.h"
#include "dn/train/kernel_trainer.h"

using namespace dn;
using Clock = std::chrono::steady_clock;

namespace {

double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

std::vector<int64_t> parseList(const std::string& text) {
  std::vector<int64_t> values;
  size_t start = 0;
  while (start < text.size()) {
    size_t end = text.find(',', start);
    if (end == std::string::npos) end = text.size();
    values.push_back(std::stoll(text.substr(start, end - start)));
    start = end + 1;
  }
  return values;
}

// Random linear radiance with some bright outliers, and aux buffers in range.
std::pair<torch::Tensor, torch::Tensor> randomInputs(int64_t batch, int64_t size, int64_t aux) {
  auto radiance =
      torch::rand({batch, 3, size, size}) * torch::rand({batch, 1, size, size}).pow(4) * 8;
  return {radiance, torch::rand({batch, aux, size, size})};
}

}  // namespace

int main(int argc, char** argv) {
  int threads = 2, steps = 10, batch = 8, crop = 64;
  KernelNetConfig config;
  config.input_buffers = defaultAuxBuffers();
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string option = argv[i], value = argv[i + 1];
    if (option == "--threads")
      threads = std::stoi(value);
    else if (option == "--steps")
      steps = std::stoi(value);
    else if (option == "--batch")
      batch = std::stoi(value);
    else if (option == "--crop")
      crop = std::stoi(value);
    else if (option == "--widths")
      config.widths = parseList(value);
    else {
      std::fprintf(stderr, "cleanse_bench: unknown option %s\n", option.c_str());
      return 1;
    }
  }
  torch::set_num_threads(threads);
  torch::manual_seed(1);
  KernelModelInfo info;
  info.net = config;
  KernelNet net(config);
  int64_t parameters = 0;
  for (const auto& p : net->parameters()) parameters += p.numel();
  std::printf(
      "kernel net: widths %s, %lld aux channels, %zu iterations of %lldx%lld, %lld parameters, %d "
      "threads\n",
      [&] {
        std::string s;
        for (auto w : config.widths) s += (s.empty() ? "" : ",") + std::to_string(w);
        return s;
      }()
          .c_str(),
      (long long)config.auxChannels(), config.dilations.size(), (long long)config.kernel_size,
      (long long)config.kernel_size, (long long)parameters, threads);

  KernelTrainer trainer(net, info, {});
  auto [radiance, aux] = randomInputs(batch, crop, config.auxChannels());
  auto target = radiance * 0.9;
  for (int i = 0; i < 2; ++i) trainer.step(radiance, aux, target);  // warm-up
  auto start = Clock::now();
  for (int i = 0; i < steps; ++i) trainer.step(radiance, aux, target);
  const double train_seconds = secondsSince(start);
  std::printf("training: batch %d of %dx%d crops: %.3f s/step, %.1f samples/s\n", batch, crop, crop,
              train_seconds / steps, steps * batch / train_seconds);

  torch::NoGradGuard no_grad;
  net->eval();
  for (int64_t size : {256, 512}) {
    auto [image, buffers] = randomInputs(1, size, config.auxChannels());
    net->forward(image, buffers);  // warm-up
    const int repeats = size <= 256 ? 3 : 2;
    start = Clock::now();
    torch::Tensor maps;
    for (int i = 0; i < repeats; ++i) maps = net->guideMaps(image, buffers);
    const double unet = secondsSince(start) / repeats;
    start = Clock::now();
    for (int i = 0; i < repeats; ++i) {
      auto x = image;
      auto guides = net->decodeGuides(maps);
      for (size_t k = 0; k < guides.size(); ++k)
        x = affinityFilter(x, guides[k].features, guides[k].bandwidth, guides[k].centre,
                           config.kernel_size, config.dilations[k]);
    }
    const double filtering = secondsSince(start) / repeats;
    const double megapixels = size * size / 1e6;
    std::printf(
        "apply %lldx%lld: %.3f s (feature UNet %.3f s, kernels %.3f s) = %.2f s per megapixel\n",
        (long long)size, (long long)size, unet + filtering, unet, filtering,
        (unet + filtering) / megapixels);
  }
  return 0;
}
