#include "doctest_torch.h"

#include <ATen/CPUGeneratorImpl.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>

#include <unistd.h>

#include "dn/nn/kernel_net.h"
#include "dn/nn/model_file.h"
#include "dn/train/kernel_trainer.h"
#include "dn/train/losses.h"

using namespace dn;
namespace fs = std::filesystem;

namespace {

struct TempDir {
  fs::path path = fs::temp_directory_path() / ("dn_kernel_net_test_" + std::to_string(::getpid()));
  TempDir() { fs::create_directories(path); }
  ~TempDir() { fs::remove_all(path); }
  std::string file(const std::string& name) const { return (path / name).string(); }
};

KernelNetConfig tinyConfig() {
  KernelNetConfig config;
  config.input_buffers = {"albedo", "normal"};
  config.widths = {8, 12};
  config.feature_dims = 4;
  config.dilations = {1, 2};
  config.kernel_size = 5;
  return config;
}

// Reference box filter with plain loops: mean over the in-image k x k
// neighbours spaced `dilation` apart, the centre weighing `centre` (others 1).
torch::Tensor naiveBox(const torch::Tensor& image, int64_t k, int64_t dilation, double centre) {
  auto out = torch::zeros_like(image);
  const int64_t c = image.size(1), h = image.size(2), w = image.size(3), r = k / 2;
  auto in = image.accessor<float, 4>();
  auto o = out.accessor<float, 4>();
  for (int64_t ch = 0; ch < c; ++ch)
    for (int64_t y = 0; y < h; ++y)
      for (int64_t x = 0; x < w; ++x) {
        double sum = 0, weight = 0;
        for (int64_t dy = -r; dy <= r; ++dy)
          for (int64_t dx = -r; dx <= r; ++dx) {
            const int64_t yy = y + dy * dilation, xx = x + dx * dilation;
            if (yy < 0 || yy >= h || xx < 0 || xx >= w) continue;
            const double wgt = (dy == 0 && dx == 0) ? centre : 1.0;
            sum += wgt * in[0][ch][yy][xx];
            weight += wgt;
          }
        o[0][ch][y][x] = float(sum / weight);
      }
  return out;
}

// A frame of flat-coloured vertical stripes whose albedo marks the edges, with
// multiplicative noise of mean 1 (so the clean image is the noise-free mean).
struct Stripes {
  torch::Tensor clean, albedo;
};

Stripes makeStripes(int64_t batch, int64_t size, torch::Generator& generator) {
  const int64_t stripes = 4;
  auto colours = torch::rand({batch, 3, 1, stripes}, generator) * 1.5 + 0.1;
  auto index = (torch::arange(size) * stripes / size).to(torch::kLong);
  auto clean = colours.index_select(3, index).expand({batch, 3, size, size}).contiguous();
  return {clean, (clean / 1.6).clamp(0.0, 1.0)};
}

torch::Tensor noisy(const torch::Tensor& clean, torch::Generator& generator) {
  // Exponential noise (a gamma of shape 1): heavy like Monte Carlo noise, mean 1.
  auto u = torch::rand(clean.sizes(), generator).clamp_min(1e-6);
  return clean * -torch::log(u);
}

torch::Tensor flatNormals(int64_t batch, int64_t size) {
  auto normal = torch::zeros({batch, 3, size, size});
  normal.narrow(1, 2, 1).fill_(1.0);
  return normal;
}

}  // namespace

TEST_CASE("SMAPE matches closed-form values") {
  auto a = torch::tensor({1.0f, 2.0f, 0.0f, 0.0f}).view({2, 2});
  auto b = torch::tensor({3.0f, 0.0f, 0.0f, 4.0f}).view({2, 2});
  // Per element |a-b| / (|a|+|b|+eps): 2/4, 2/2, 0/0 (0 with eps), 4/4; mean over all.
  CHECK(smapeLoss(a, b, 0.01).item<double>() ==
        doctest::Approx((2.0 / 4.01 + 2.0 / 2.01 + 0.0 + 4.0 / 4.01) / 4).epsilon(1e-6));
  // Relative per element: the same 10% error costs the same in a dark and a
  // bright pixel (an image-level ratio would let the bright one dominate).
  auto truth = torch::tensor({0.01f, 100.0f}), dark_off = torch::tensor({0.011f, 100.0f});
  auto bright_off = torch::tensor({0.01f, 110.0f});
  CHECK(smapeLoss(dark_off, truth, 0.0).item<double>() ==
        doctest::Approx(smapeLoss(bright_off, truth, 0.0).item<double>()).epsilon(1e-5));
  CHECK(smapeLoss(b, a, 0.01).item<double>() ==
        doctest::Approx(smapeLoss(a, b, 0.01).item<double>()));
  CHECK(smapeLoss(a, a, 0.01).item<double>() == 0.0);
  // The clamp to [0, 6] of the kernel-net loss: 10 vs 6 costs nothing.
  auto bright = torch::full({1, 3, 2, 2}, 10.0f), six = torch::full({1, 3, 2, 2}, 6.0f);
  CHECK(kernelNetLoss(bright, six, 0.01).item<double>() == 0.0);
  CHECK_THROWS(smapeLoss(a, b.view({4}), 0.0));
}

TEST_CASE("kernels are normalised: a constant image stays constant") {
  torch::manual_seed(3);
  auto image = torch::full({2, 3, 17, 13}, 0.7f);
  auto features = torch::randn({2, 6, 17, 13}) * 3;
  auto bandwidth = torch::rand({2, 1, 17, 13}) * 5;
  auto centre = torch::rand({2, 1, 17, 13}) + 1e-3;
  for (int64_t dilation : {1, 3, 8}) {
    auto out = affinityFilter(image, features, bandwidth, centre, 5, dilation);
    CHECK(out.sizes() == image.sizes());
    CHECK((out - 0.7).abs().max().item<double>() < 1e-5);
  }
  // The whole network, with random weights and aux buffers.
  KernelNet net(tinyConfig());
  torch::NoGradGuard no_grad;
  auto aux = torch::rand({2, 6, 17, 13});
  auto out = net->forward(torch::full({2, 3, 17, 13}, 2.5f), aux);
  CHECK((out - 2.5).abs().max().item<double>() < 1e-4);
}

TEST_CASE("identical features give a box filter, masked at the border") {
  torch::manual_seed(4);
  auto image = torch::rand({1, 3, 11, 9});
  auto features = torch::full({1, 4, 11, 9}, 0.3f);
  auto bandwidth = torch::rand({1, 1, 11, 9}) * 4;
  for (double centre : {1.0, 3.5}) {
    auto out = affinityFilter(image, features, bandwidth, torch::full({1, 1, 11, 9}, centre), 5, 2);
    CHECK(torch::allclose(out, naiveBox(image, 5, 2, centre), 1e-5, 1e-6));
  }
  // Other pixels weigh exp(-bandwidth * distance): a far feature gets no weight.
  auto split = torch::zeros({1, 1, 11, 9});
  split.narrow(3, 0, 4).fill_(100.0f);
  auto out =
      affinityFilter(image, split, torch::ones({1, 1, 11, 9}), torch::ones({1, 1, 11, 9}), 3, 1);
  auto left = naiveBox(image.narrow(3, 0, 4).contiguous(), 3, 1, 1.0);
  CHECK(torch::allclose(out.narrow(3, 0, 4), left, 1e-5, 1e-6));
}

TEST_CASE("demodulation filters radiance / albedo and keeps texture") {
  torch::manual_seed(15);
  auto config = tinyConfig();
  config.demodulate = true;
  KernelNet net(config);
  torch::NoGradGuard no_grad;
  auto aux = torch::rand({1, 6, 14, 10});
  const auto modulation = aux.narrow(1, 0, 3) + kDemodulationEps;
  // Flat shading times any texture comes out unchanged, whatever the kernels.
  auto textured = 1.7 * modulation;
  CHECK(torch::allclose(net->forward(textured, aux), textured, 1e-4, 1e-5));
  // With a zero head: box filters of the shading, multiplied back by the albedo.
  net->head->weight.zero_();
  auto radiance = torch::rand({1, 3, 14, 10}) * 4;
  auto shading = (radiance / modulation).contiguous();
  auto expected = naiveBox(naiveBox(shading, 5, 1, 1.0), 5, 2, 1.0) * modulation;
  CHECK(torch::allclose(net->forward(radiance, aux), expected, 1e-4, 1e-5));
  config.input_buffers = {"normal"};
  CHECK_THROWS_AS(config.validate(), std::invalid_argument);
}

TEST_CASE("the network with a zero head filters like iterated box filters") {
  torch::manual_seed(5);
  KernelNet net(tinyConfig());
  {
    torch::NoGradGuard no_grad;
    net->head->weight.zero_();  // features all 0, bandwidth 1, centre weight 1
  }
  auto radiance = torch::rand({1, 3, 14, 10}) * 4;
  auto aux = torch::rand({1, 6, 14, 10});
  torch::NoGradGuard no_grad;
  auto out = net->forward(radiance, aux);
  auto expected = naiveBox(naiveBox(radiance, 5, 1, 1.0), 5, 2, 1.0);
  CHECK(torch::allclose(out, expected, 1e-5, 1e-5));
}

TEST_CASE("banded filtering equals one pass") {
  torch::manual_seed(6);
  auto image = torch::rand({2, 3, 23, 19});
  auto features = torch::randn({2, 5, 23, 19});
  auto bandwidth = torch::rand({2, 1, 23, 19});
  auto centre = torch::rand({2, 1, 23, 19}) + 0.1;
  auto whole = affinityFilter(image, features, bandwidth, centre, 5, 4);
  auto banded = affinityFilter(image, features, bandwidth, centre, 5, 4, 1);  // one row per band
  CHECK(torch::allclose(whole, banded, 1e-6, 1e-7));
  {
    torch::NoGradGuard no_grad;  // the inference path (strided views instead of unfold)
    CHECK(torch::allclose(whole, affinityFilter(image, features, bandwidth, centre, 5, 4), 1e-6,
                          1e-7));
    CHECK(torch::allclose(whole, affinityFilter(image, features, bandwidth, centre, 5, 4, 1), 1e-6,
                          1e-7));
  }
  // Outputs lie within the inputs' range (convex combinations).
  CHECK(whole.min().item<double>() >= image.min().item<double>() - 1e-6);
  CHECK(whole.max().item<double>() <= image.max().item<double>() + 1e-6);
}

TEST_CASE("affinity filter gradients match finite differences") {
  torch::manual_seed(12);
  auto options = torch::TensorOptions().dtype(torch::kDouble);
  std::vector<torch::Tensor> inputs = {
      torch::rand({1, 2, 7, 6}, options), torch::randn({1, 3, 7, 6}, options),
      torch::rand({1, 1, 7, 6}, options) + 0.2, torch::rand({1, 1, 7, 6}, options) + 0.2};
  for (auto& input : inputs) input.requires_grad_(true);
  const auto projection = torch::randn({1, 2, 7, 6}, options);
  auto objective = [&] {
    return (affinityFilter(inputs[0], inputs[1], inputs[2], inputs[3], 3, 2) * projection).sum();
  };
  objective().backward();
  torch::NoGradGuard no_grad;
  const double h = 1e-6;
  for (auto& input : inputs)
    for (int64_t index : {0, 5, 17, 41}) {
      auto flat = input.view({-1});
      if (index >= flat.numel()) continue;
      const double saved = flat[index].item<double>();
      flat[index] = saved + h;
      const double up = objective().item<double>();
      flat[index] = saved - h;
      const double down = objective().item<double>();
      flat[index] = saved;
      CHECK(input.grad().view({-1})[index].item<double>() ==
            doctest::Approx((up - down) / (2 * h)).epsilon(1e-5));
    }
}

TEST_CASE("gradients reach every parameter") {
  torch::manual_seed(7);
  KernelNet net(tinyConfig());
  auto radiance = torch::rand({2, 3, 16, 16}) * 3;
  auto loss = kernelNetLoss(net->forward(radiance, torch::rand({2, 6, 16, 16})),
                            torch::rand({2, 3, 16, 16}), 1e-2);
  loss.backward();
  for (const auto& item : net->named_parameters()) {
    INFO(item.key());
    REQUIRE(item.value().grad().defined());
    CHECK(item.value().grad().abs().sum().item<double>() > 0.0);
  }
}

TEST_CASE("kernels never die: a saturated head still passes gradients") {
  // Huge head outputs push every bandwidth to its bound and features far apart;
  // neighbour weights must stay above 0 so training can come back.
  torch::manual_seed(13);
  KernelNet net(tinyConfig());
  {
    torch::NoGradGuard no_grad;
    net->head->weight.mul_(1e4);
  }
  auto radiance = torch::rand({1, 3, 16, 16}) * 3;
  auto out = net->forward(radiance, torch::rand({1, 6, 16, 16}));
  CHECK(torch::isfinite(out).all().item<bool>());
  kernelNetLoss(out, torch::rand({1, 3, 16, 16}), 1e-2).backward();
  for (const auto& item : net->named_parameters()) {
    INFO(item.key());
    CHECK(item.value().grad().abs().sum().item<double>() > 0.0);
  }
}

TEST_CASE("odd sizes and no aux buffers work") {
  auto config = tinyConfig();
  config.input_buffers = {};
  config.widths = {4, 6, 8};
  KernelNet net(config);
  torch::NoGradGuard no_grad;
  auto out = net->forward(torch::rand({1, 3, 7, 5}), torch::Tensor());
  CHECK(out.sizes() == torch::IntArrayRef({1, 3, 7, 5}));
  CHECK(torch::isfinite(out).all().item<bool>());
}

TEST_CASE("bad configurations are rejected") {
  auto config = tinyConfig();
  config.kernel_size = 4;
  CHECK_THROWS_AS(config.validate(), std::invalid_argument);
  config = tinyConfig();
  config.input_buffers = {"no_such_buffer"};
  CHECK_THROWS_AS(config.validate(), std::invalid_argument);
  config = tinyConfig();
  config.tonemap = "bogus";
  CHECK_THROWS_AS(config.validate(), std::invalid_argument);
  CHECK_THROWS_AS(kernelTaskFromName("sharpen"), std::invalid_argument);
}

TEST_CASE("model files round-trip; damaged files fail naming the file") {
  TempDir dir;
  torch::manual_seed(8);
  KernelModelInfo info;
  info.net = tinyConfig();
  info.net.demodulate = true;
  info.task = KernelTask::Denoise;
  info.notes["data"] = "/some/data set";
  KernelNet net(info.net);
  const auto path = dir.file("net.dnk");
  saveKernelModel(path, info, net);
  auto loaded = loadKernelModel(path);
  CHECK(kernelModelInfoToText(loaded.info) == kernelModelInfoToText(info));
  CHECK(loaded.info.task == KernelTask::Denoise);
  CHECK(loaded.info.net.demodulate);
  // Model files from before demodulation existed lack the key: no demodulation.
  auto legacy = kernelModelInfoToText(info);
  legacy.erase(legacy.find("kernel.demodulate=1\n"), std::string("kernel.demodulate=1\n").size());
  CHECK_FALSE(kernelModelInfoFromText(legacy, "legacy").net.demodulate);
  // Older still: no centre-weight key either, so the weights' meaning is unknown.
  const std::string centre_key = "kernel.centre_weight=sigmoid4\n";
  REQUIRE(legacy.find(centre_key) != std::string::npos);
  auto oldest = legacy;
  oldest.erase(oldest.find(centre_key), centre_key.size());
  CHECK_THROWS_WITH_AS(kernelModelInfoFromText(oldest, "oldest.dnk"),
                       doctest::Contains("centre weight"), ModelError);
  auto other_centre = legacy;
  other_centre.replace(other_centre.find(centre_key), centre_key.size(),
                       "kernel.centre_weight=softplus\n");
  CHECK_THROWS_WITH_AS(kernelModelInfoFromText(other_centre, "other.dnk"),
                       doctest::Contains("softplus"), ModelError);
  CHECK(loaded.info.notes.at("data") == "/some/data set");
  auto radiance = torch::rand({1, 3, 12, 12}), aux = torch::rand({1, 6, 12, 12});
  torch::NoGradGuard no_grad;
  net->eval();
  CHECK(torch::equal(net->forward(radiance, aux), loaded.net->forward(radiance, aux)));

  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  auto write = [&](const std::string& name, const std::string& content) {
    std::ofstream(dir.file(name), std::ios::binary) << content;
    return dir.file(name);
  };
  auto expectError = [](const std::string& file, const std::string& words) {
    try {
      loadKernelModel(file);
      FAIL("no error for " << file);
    } catch (const ModelError& error) {
      const std::string what = error.what();
      CHECK(what.find(file) == 0);
      CHECK(what.find(words) != std::string::npos);
      CHECK(what.find('\n') == std::string::npos);
    }
  };
  std::string flipped = bytes;
  flipped[flipped.size() - 100] ^= 0x20;
  expectError(write("flipped.dnk", flipped), "checksum");
  expectError(write("short.dnk", bytes.substr(0, bytes.size() / 2)), "truncated");
  expectError(write("text.dnk", "hello\n"), "not a kernel-model");
  expectError(dir.file("missing.dnk"), "cannot open");
  torch::serialize::OutputArchive empty;
  writeArchiveFile(dir.file("other.dnk"), "model", "x=1\n", empty);
  expectError(dir.file("other.dnk"), "expected a kernel-model");
  writeArchiveFile(dir.file("badmeta.dnk"), "kernel-model", "task=denoise\n", empty);
  expectError(dir.file("badmeta.dnk"), "lacks");
  auto bad_flag = kernelModelInfoToText(info);
  bad_flag.replace(bad_flag.find("kernel.demodulate=1"), 19, "kernel.demodulate=7");
  writeArchiveFile(dir.file("badflag.dnk"), "kernel-model", bad_flag, empty);
  expectError(dir.file("badflag.dnk"), "demodulate");
  // Metadata naming a different architecture than the stored weights.
  auto wider = info;
  wider.net.widths = {8, 16};
  torch::serialize::OutputArchive weights;
  net->save(weights);
  writeArchiveFile(dir.file("mismatch.dnk"), "kernel-model", kernelModelInfoToText(wider), weights);
  expectError(dir.file("mismatch.dnk"), "weight");
}

TEST_CASE("checkpoints resume exactly") {
  TempDir dir;
  torch::manual_seed(9);
  torch::Generator generator = at::detail::createCPUGenerator(11);
  std::vector<Stripes> data;
  std::vector<torch::Tensor> inputs, targets;
  for (int i = 0; i < 5; ++i) {
    data.push_back(makeStripes(2, 16, generator));
    inputs.push_back(noisy(data.back().clean, generator));
    targets.push_back(noisy(data.back().clean, generator));
  }
  auto aux = [&](int i) { return torch::cat({data[i].albedo, flatNormals(2, 16)}, 1); };
  KernelModelInfo info;
  info.net = tinyConfig();
  KernelTrainer first(KernelNet(info.net), info, {});
  for (int i = 0; i < 3; ++i) first.step(inputs[i], aux(i), targets[i]);
  first.saveCheckpoint(dir.file("run.ckpt"), {{"loader_position", "123"}});
  const double a = first.step(inputs[3], aux(3), targets[3]);
  const double b = first.step(inputs[4], aux(4), targets[4]);

  torch::manual_seed(1234);  // different initial weights, all overwritten by the checkpoint
  KernelTrainer second(KernelNet(info.net), info, {});
  auto state = second.loadCheckpoint(dir.file("run.ckpt"));
  CHECK(state.at("loader_position") == "123");
  CHECK(second.stepCount() == 3);
  CHECK(second.step(inputs[3], aux(3), targets[3]) == doctest::Approx(a).epsilon(1e-6));
  CHECK(second.step(inputs[4], aux(4), targets[4]) == doctest::Approx(b).epsilon(1e-6));

  auto other = info;
  other.net.feature_dims = 5;
  KernelTrainer mismatched(KernelNet(other.net), other, {});
  CHECK_THROWS_AS(mismatched.loadCheckpoint(dir.file("run.ckpt")), ModelError);
  CHECK_THROWS_AS(second.loadCheckpoint(dir.file("missing.ckpt")), ModelError);
}

TEST_CASE("Noise2Noise training on noisy stripes lowers the error against the clean image") {
  torch::manual_seed(10);
  torch::Generator generator = at::detail::createCPUGenerator(12);
  KernelModelInfo info;
  info.net = tinyConfig();
  KernelTrainer trainer(KernelNet(info.net), info, {3e-3, 0, 0.9, 1.0, 1e-2});
  auto validation = makeStripes(4, 24, generator);
  auto validation_input = noisy(validation.clean, generator);
  auto validation_aux = torch::cat({validation.albedo, flatNormals(4, 24)}, 1);
  auto errorAgainstClean = [&] {
    return trainer.evaluate(validation_input, validation_aux, validation.clean);
  };
  const double before = errorAgainstClean();
  const double noisy_error = kernelNetLoss(validation_input, validation.clean, 1e-2).item<double>();
  for (int step = 0; step < 60; ++step) {
    auto batch = makeStripes(4, 24, generator);
    auto aux = torch::cat({batch.albedo, flatNormals(4, 24)}, 1);
    trainer.step(noisy(batch.clean, generator), aux, noisy(batch.clean, generator));
  }
  const double after = errorAgainstClean();
  MESSAGE("SMAPE vs clean: noisy " << noisy_error << ", at init " << before << ", trained "
                                   << after);
  CHECK(before < noisy_error);   // even the initial kernels average noise away
  CHECK(after < 0.85 * before);  // learning to stop at the albedo edges does better
}
