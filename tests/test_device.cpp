// Device placement (dn/infer/device.h and DenoiseOptions::device). Without a GPU
// (CI, the CPU-only Debian LibTorch): CUDA and half precision are refused with
// a clear error before any work, and the diffusion models refuse every device
// but the CPU; the pieces of the GPU path that run anywhere (images as they
// cross, the staging copies, a frame's uploads and the gate on them, the
// autoexposure as tensor operations) are checked on the CPU. With one
// (bench/gpu/check_cuda.sh): the OIDN base's modes and the gate on CUDA agree
// with the CPU, in float and in half, and pinned uploads arrive intact.
#include "doctest_torch.h"
#include "tiny_models.h"

#include <ATen/CPUGeneratorImpl.h>

#include <cstring>
#include <tuple>

#include "dn/infer/denoiser.h"
#include "dn/infer/device.h"
#include "dn/infer/frame_uploads.h"
#include "dn/infer/noise_estimate.h"
#include "dn/infer/oidn_filter.h"
#include "dn/metrics.h"
#include "dn/nn/host_staging.h"
#include "dn/nn/model_inputs.h"
#include "dn/tonemap.h"

using namespace dn;

namespace {

const std::string kModel = std::string(DN_SOURCE_DIR) + "/models/default.dnm";

Image randomImage(int w, int h, int c, double scale, uint64_t seed) {
  auto generator = at::detail::createCPUGenerator(seed);
  return tensorToImage(torch::rand({1, c, h, w}, generator, torch::kFloat) * scale);
}

// A render with albedo, normal and Cycles' diffuse passes; its size is not a
// multiple of OIDN's alignment, so the padding is exercised too.
FrameBuffers syntheticFrame(int width, int height) {
  FrameBuffers frame;
  frame.width = width;
  frame.height = height;
  frame.buffers["albedo"] = randomImage(width, height, 3, 0.9, 1);
  frame.buffers["normal"] = randomImage(width, height, 3, 1.0, 2);
  frame.buffers["diffuse_color"] = frame.buffers["albedo"];
  frame.buffers["diffuse_direct"] = randomImage(width, height, 3, 2.0, 3);
  frame.buffers["diffuse_indirect"] = randomImage(width, height, 3, 0.5, 4);
  Image color = randomImage(width, height, 3, 1.0, 5);
  for (std::size_t i = 0; i < color.pixels.size(); ++i)
    color.pixels[i] +=
        frame.buffers["albedo"].pixels[i] *
        (frame.buffers["diffuse_direct"].pixels[i] + frame.buffers["diffuse_indirect"].pixels[i]);
  frame.buffers["color"] = color;
  return frame;
}

std::string messageOf(const std::function<void()>& action) {
  try {
    action();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

struct Mode {
  const char* name;
  DenoiseOptions options;
};

std::vector<Mode> modes() {
  DenoiseOptions base, prefilter, split, control;
  base.prefilter = false;
  base.lightPaths = false;
  base.control = prefilter.control = split.control = ControlUse::Never;
  prefilter.lightPaths = false;
  split.lightPaths = true;
  control.control = ControlUse::Always;
  return {{"base", base}, {"prefilter", prefilter}, {"split", split}, {"control", control}};
}

}  // namespace

TEST_CASE("device names: cpu, cuda and cuda:N; anything else is refused in one line") {
  CHECK(parseDevice("cpu") == torch::Device(torch::kCPU));
  for (const char* bad : {"gpu", "CPU", "cuda:x", "cuda:-1", "mps", ""}) {
    CAPTURE(bad);
    const std::string message = messageOf([&] { parseDevice(bad); });
    CHECK(message.find("expected cpu, cuda or cuda:N") != std::string::npos);
    CHECK(message.find('\n') == std::string::npos);
  }
  CHECK_THROWS_AS(checkDeviceAvailable(torch::Device(c10::DeviceType::Meta)),
                  std::invalid_argument);
  CHECK_THROWS_AS(freeDeviceMemory(torch::Device(torch::kCPU)), std::invalid_argument);
}

TEST_CASE("CUDA is refused where it is not available, and its index checked where it is") {
  if (!torch::cuda::is_available()) {
    const std::string message = messageOf([] { parseDevice("cuda"); });
    CHECK(message ==
          "device 'cuda': no CUDA device is available to this LibTorch build (a "
          "CPU-only LibTorch, or no GPU or driver visible)");
    CHECK_THROWS_AS(parseDevice("cuda:0"), std::invalid_argument);
    // The denoiser itself does not fall back to the CPU either.
    const Denoiser denoiser = Denoiser::fromFile(kModel);
    DenoiseOptions options;
    options.device = torch::Device(torch::kCUDA);
    CHECK_THROWS(denoiser.denoise(syntheticFrame(40, 24), options));
  } else {
    const int64_t count = int64_t(torch::cuda::device_count());
    MESSAGE(count << " CUDA device(s)");
    CHECK(parseDevice("cuda") == torch::Device(torch::kCUDA));
    CHECK(parseDevice("cuda:0") == torch::Device(torch::kCUDA, 0));
    // A CUDA build of the core asks the runtime (bench/gpu/check_cuda.sh builds one).
    const std::optional<double> free = freeDeviceMemory(torch::Device(torch::kCUDA));
    MESSAGE("free on cuda:0: " << (free ? std::to_string(*free / 1e9) + " GB" : "not asked"));
    if (free) CHECK(*free > 0);
    const std::string past = "cuda:" + std::to_string(count);
    CHECK(messageOf([&] { parseDevice(past); }).find("CUDA device(s) present") !=
          std::string::npos);
  }
}

TEST_CASE("a diffusion model runs on the CPU only, and says so before any work") {
  ModelInfo info;
  info.base = tinyUNetConfig();
  info.respacing = "4";
  LoadedModel loaded{info, buildDenoiser(info)};
  const Denoiser denoiser(loaded);
  FrameBuffers frame;
  frame.width = frame.height = 16;
  frame.buffers["color"] = randomImage(16, 16, 3, 0.5, 9);
  DenoiseOptions options;
  options.device = torch::Device(torch::kCUDA);
  CHECK(messageOf([&] { denoiser.denoise(frame, options); }).find("runs on the CPU only") !=
        std::string::npos);
  options.device = torch::Device(torch::kCPU);
  const DenoiseResult result = denoiser.denoise(frame, options);
  CHECK(result.color.sameShape(frame.get("color")));
}

TEST_CASE("the OIDN base's modes on the device asked for: the CPU exactly, CUDA to 60 dB") {
  const Denoiser denoiser = Denoiser::fromFile(kModel);
  const FrameBuffers frame = syntheticFrame(72, 40);
  const bool cuda = torch::cuda::is_available();
  // Strict float32 on the GPU: TF32 convolutions (LibTorch's default) are a
  // speed choice for the caller, not what this test compares.
  if (cuda) at::globalContext().setAllowTF32CuDNN(false);
  for (const Mode& mode : modes()) {
    CAPTURE(mode.name);
    DenoiseOptions onCpu = mode.options;
    onCpu.device = torch::Device(torch::kCPU);
    const DenoiseResult reference = denoiser.denoise(frame, onCpu);
    CHECK(reference.color.pixels == denoiser.denoise(frame, mode.options).color.pixels);
    if (std::string(mode.name) != "control")
      CHECK(reference.prefiltered == (std::string(mode.name) != "base"));
    CHECK(reference.lightPathsSplit == (std::string(mode.name) == "split"));
    CHECK(reference.steered == (std::string(mode.name) == "control"));
    if (!cuda) continue;
    DenoiseOptions onGpu = mode.options;
    onGpu.device = torch::Device(torch::kCUDA);
    const DenoiseResult gpu = denoiser.denoise(frame, onGpu);
    const double psnr = metrics::compare(reference.color, gpu.color, {"psnr"}).values.at("psnr");
    MESSAGE(std::string(mode.name) << ": CUDA against CPU " << psnr << " dB");
    CHECK(psnr >= 60.0);
  }
}

TEST_CASE("half precision runs on CUDA only: refused elsewhere in one line, before any work") {
  const Denoiser denoiser = Denoiser::fromFile(kModel);
  const FrameBuffers frame = syntheticFrame(72, 40);
  DenoiseOptions options;
  options.precision = Precision::Float16;
  const std::string message = messageOf([&] { denoiser.denoise(frame, options); });
  CHECK(message == "precision fp16: half runs on CUDA only (on the cpu: float or bf16)");
  CHECK(precisionFromName("fp16") == Precision::Float16);
  CHECK(precisionFromName("bf16") == Precision::BFloat16);
  CHECK(precisionFromName("float") == Precision::Float);
  CHECK_FALSE(precisionFromName("half").has_value());
  if (!torch::cuda::is_available()) return;
  at::globalContext().setAllowTF32CuDNN(false);
  for (const Mode& mode : modes()) {
    CAPTURE(mode.name);
    const DenoiseResult reference = denoiser.denoise(frame, mode.options);
    DenoiseOptions half = mode.options;
    half.device = torch::Device(torch::kCUDA);
    half.precision = Precision::Float16;
    const DenoiseResult gpu = denoiser.denoise(frame, half);
    const double psnr = metrics::compare(reference.color, gpu.color, {"psnr"}).values.at("psnr");
    MESSAGE(std::string(mode.name) << ": CUDA in half against the CPU in float " << psnr << " dB");
    CHECK(psnr >= 40.0);  // a sanity bound: check_cuda.sh reports the agreement at 1080p
    CHECK(psnr < 200.0);  // and it did run in half
  }
}

TEST_CASE("images cross to a device exactly") {
  Image image = randomImage(37, 11, 3, 4.0, 21);
  image.pixels[5] = NAN;
  const torch::Tensor original = torch::from_blob(image.pixels.data(), {int64_t(image.size())});
  // On the CPU imageToDevice is imageToTensor; on CUDA the round trip is exact.
  CHECK(torch::equal(imageToDevice(image, torch::kCPU).nan_to_num(0),
                     imageToTensor(image).nan_to_num(0)));
  if (torch::cuda::is_available()) {
    const torch::Tensor onGpu = imageToDevice(image, torch::Device(torch::kCUDA));
    CHECK(onGpu.is_cuda());
    Image round = tensorToImage(onGpu);
    CHECK(torch::equal(torch::from_blob(round.pixels.data(), {int64_t(round.size())}).nan_to_num(0),
                       original.nan_to_num(0)));
  }
}

TEST_CASE("buffers cross through the staging copies byte for byte") {
  // Sizes around the copy's 1 MiB slices: none, one short slice, uneven ones.
  for (const std::size_t floats : {std::size_t(0), std::size_t(1), std::size_t(1000),
                                   (std::size_t(1) << 18) + 3, (std::size_t(5) << 18) + 17}) {
    CAPTURE(floats);
    auto generator = at::detail::createCPUGenerator(floats);
    const torch::Tensor source = torch::randn({int64_t(floats)}, generator);
    const float* from = source.data_ptr<float>();
    const std::size_t bytes = floats * sizeof(float);
    std::vector<float> copied(floats, -1.0f);
    parallelCopy(copied.data(), from, bytes);
    CHECK(std::memcmp(copied.data(), from, bytes) == 0);
    const torch::Tensor staged = stagedCopy(from, {int64_t(floats)}, false);
    CHECK(std::memcmp(staged.data_ptr<float>(), from, bytes) == 0);
    const torch::Tensor onCpu = floatsToDevice(from, {int64_t(floats)}, torch::kCPU);
    if (floats > 0) CHECK(onCpu.data_ptr<float>() != from);  // a copy, not a view
    std::vector<float> back(floats, -1.0f);
    floatsToHost(onCpu, back.data());
    CHECK(std::memcmp(back.data(), from, bytes) == 0);
  }
  if (!torch::cuda::is_available()) return;
  CHECK(stagedCopy(std::vector<float>(8).data(), {8}, true).is_pinned());
  // Two uploads of one size in a row: the second's staging may be the first's
  // block again only once the device has read it.
  const torch::Tensor a = torch::rand({3 << 20}), b = torch::rand({3 << 20});
  const torch::Device cuda(torch::kCUDA);
  const torch::Tensor onA = floatsToDevice(a.data_ptr<float>(), a.sizes(), cuda);
  const torch::Tensor onB = floatsToDevice(b.data_ptr<float>(), b.sizes(), cuda);
  for (const auto& [host, onDevice] : {std::pair(a, onA), std::pair(b, onB)}) {
    CHECK(onDevice.is_cuda());
    std::vector<float> back(host.numel());
    floatsToHost(onDevice, back.data());
    CHECK(std::memcmp(back.data(), host.data_ptr<float>(), host.nbytes()) == 0);
  }
}

TEST_CASE("a frame's buffers are sent once, and the gate reads the same copies") {
  FrameBuffers frame = syntheticFrame(72, 40);
  frame.buffers["depth"] = randomImage(72, 40, 1, 50.0, 6);
  const torch::Tensor input = imageToTensor(frame.get("color"));
  const torch::Tensor output = input * 0.5 + 0.1 * torch::rand_like(input);
  const NoiseLeft loops = measureNoiseLeft(input, output, frame);
  std::vector<torch::Device> devices = {torch::kCPU};
  if (torch::cuda::is_available()) devices.emplace_back(torch::kCUDA);
  for (const torch::Device& device : devices) {
    CAPTURE(device.str());
    FrameUploads uploads(frame, device);
    CHECK(uploads.holds(frame));
    CHECK_FALSE(uploads.holds(FrameBuffers(frame)));
    const torch::Tensor& albedo = uploads.stored("albedo");
    CHECK(albedo.device().type() == device.type());  // cuda:0 for cuda
    CHECK(albedo.is_same(uploads.stored("albedo")));
    CHECK(torch::equal(albedo.cpu(), imageToTensor(frame.get("albedo"))));
    // The gate given the uploads measures what it measures from the frame.
    const torch::Tensor in = input.to(device), out = output.to(device);
    const NoiseLeft fromFrame = measureNoiseLeftByTensors(in, out, frame);
    const NoiseLeft fromUploads = measureNoiseLeftByTensors(in, out, uploads);
    CHECK(fromUploads.input == fromFrame.input);
    CHECK(fromUploads.output == fromFrame.output);
    const NoiseLeft dispatched = measureNoiseLeft(in, out, uploads);
    CHECK(dispatched.input == doctest::Approx(loops.input).epsilon(1e-5));
    CHECK(dispatched.output == doctest::Approx(loops.output).epsilon(1e-5));
    if (device.is_cpu()) CHECK(dispatched.input == loops.input);  // the CPU's own loops
  }
}

TEST_CASE("the default's gate on the device asked for: the CPU exactly, CUDA to float rounding") {
  const Denoiser denoiser = Denoiser::fromFile(kModel);
  FrameBuffers frame = syntheticFrame(72, 40);
  frame.buffers["depth"] = randomImage(72, 40, 1, 50.0, 6);
  DenoiseOptions onCpu;
  onCpu.device = torch::Device(torch::kCPU);
  const DenoiseResult reference = denoiser.denoise(frame, onCpu);
  REQUIRE(reference.noiseLeft);
  const DenoiseResult byDefault = denoiser.denoise(frame, DenoiseOptions());
  CHECK(reference.color.pixels == byDefault.color.pixels);
  CHECK(reference.noiseLeft->input == byDefault.noiseLeft->input);
  CHECK(reference.noiseLeft->output == byDefault.noiseLeft->output);
  if (!torch::cuda::is_available()) return;
  at::globalContext().setAllowTF32CuDNN(false);
  DenoiseOptions onGpu;
  onGpu.device = torch::Device(torch::kCUDA);
  const DenoiseResult gpu = denoiser.denoise(frame, onGpu);
  REQUIRE(gpu.noiseLeft);
  CHECK(gpu.steered == reference.steered);
  CHECK(gpu.noiseLeft->input == doctest::Approx(reference.noiseLeft->input).epsilon(1e-4));
  CHECK(gpu.noiseLeft->output == doctest::Approx(reference.noiseLeft->output).epsilon(1e-2));
}

TEST_CASE("OIDN's autoexposure made where the colour is agrees with libtonemap's") {
  std::vector<torch::Device> devices = {torch::kCPU};
  if (torch::cuda::is_available()) devices.emplace_back(torch::kCUDA);
  for (auto [width, height, channels] : {std::tuple(72, 40, 3), std::tuple(1920 / 8, 1080 / 8, 3),
                                         std::tuple(33, 17, 1), std::tuple(5, 3, 3)}) {
    Image color = randomImage(width, height, channels, 8.0, uint64_t(width));
    color.pixels[0] = NAN;
    color.pixels[7] = INFINITY;
    color.pixels[9] = -3.0f;
    const float expected = tonemap::oidnExposure(color);
    for (const torch::Device& device : devices) {
      CAPTURE(width);
      CAPTURE(device.str());
      const float made = oidnExposureOnDevice(imageToDevice(color, device)).item<float>();
      CHECK(made == doctest::Approx(expected).epsilon(1e-5));
    }
  }
  // Bins whose edges fall between pixels (72 / 5 = 14.4): column 14 is in the
  // second bin, as integer division puts it. One bright column in twelve
  // weighs on its bin's mean.
  Image columns(72, 40, 3, 0.001f);
  for (int y = 0; y < columns.height; ++y)
    for (int x = 14; x < columns.width; x += 12)
      std::fill_n(columns.pixels.begin() + (std::size_t(y) * columns.width + x) * 3, 3, 1000.0f);
  CHECK(oidnExposureOnDevice(imageToTensor(columns)).item<float>() ==
        doctest::Approx(tonemap::oidnExposure(columns)).epsilon(1e-5));
  const Image dark(16, 16, 3);  // every bin below the threshold: OIDN's exposure of 1
  CHECK(oidnExposureOnDevice(imageToTensor(dark)).item<float>() == 1.0f);
  CHECK(tonemap::oidnExposure(dark) == 1.0f);
}
