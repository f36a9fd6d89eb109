// The pretrained base: OIDN's networks in LibTorch. Sizes against OIDN's own
// parameter counts, its transfer function and autoexposure, the identification
// of the blobs in a library, the model file, and agreement with OIDN's output
// on a committed crop (testdata/oidn, made by tests/make_oidn_fixture.py).
#include "doctest_torch.h"
#include "tza_writer.h"

#include <cmath>
#include <filesystem>
#include <fstream>

#include <unistd.h>

#include "dn/infer/denoiser.h"
#include "dn/infer/oidn_filter.h"
#include "dn/io/buffer_io.h"
#include "dn/metrics.h"
#include "dn/nn/oidn_import.h"
#include "dn/tonemap.h"

using namespace dn;
namespace fs = std::filesystem;

namespace {

const std::string kModel = std::string(DN_SOURCE_DIR) + "/models/oidn.dnm";
const std::string kCrop = std::string(DN_TESTDATA) + "/oidn/crop.exr";
const std::string kOidnOut = std::string(DN_TESTDATA) + "/oidn/crop_oidn.exr";

int64_t parameterCount(torch::nn::Module& module) {
  int64_t n = 0;
  for (const auto& p : module.parameters()) n += p.numel();
  return n;
}

// PSNR (dB) of `a` against `b` after the Reinhard tonemap, as dnmetrics reports it.
double reinhardPsnr(const Image& a, const Image& b) {
  return metrics::compare(b, a, {"psnr"}).values.at("psnr");
}

double maxAbsDifference(const Image& a, const Image& b) {
  double most = 0.0;
  for (size_t i = 0; i < a.pixels.size(); ++i)
    most = std::max(most, double(std::abs(a.pixels[i] - b.pixels[i])));
  return most;
}

// A stand-in for OIDN's core library: every one of its 23 blobs with the right
// shapes in the right order, each tensor filled with its blob's index, between
// stretches of other bytes. `skip` leaves one blob out; `reshape` gives one a
// wrong shape.
std::string fakeOidnLibrary(int skip = -1, int reshape = -1) {
  struct Net {
    OidnArch arch;
    int64_t in;
  };
  const Net nets[] = {{OidnArch::Default, 3}, {OidnArch::Large, 3},   {OidnArch::Default, 3},
                      {OidnArch::Small, 3},   {OidnArch::Default, 6}, {OidnArch::Small, 6},
                      {OidnArch::Default, 9}, {OidnArch::Small, 9},   {OidnArch::Default, 9},
                      {OidnArch::Small, 9},   {OidnArch::Large, 9},   {OidnArch::Default, 3},
                      {OidnArch::Small, 3},   {OidnArch::Default, 6}, {OidnArch::Small, 6},
                      {OidnArch::Default, 9}, {OidnArch::Small, 9},   {OidnArch::Default, 9},
                      {OidnArch::Small, 9},   {OidnArch::Default, 3}, {OidnArch::Large, 3},
                      {OidnArch::Default, 3}, {OidnArch::Default, 3}};
  std::string library =
      "\x7F"
      "ELF fake library";
  for (int i = 0; i < 23; ++i) {
    if (i == skip) continue;
    const uint16_t value = 0x3C00 + uint16_t(i);  // 1 + i / 1024 as half
    std::vector<test::TzaTensorSpec> tensors;
    for (const auto& conv : oidnConvs({nets[i].arch, i == reshape ? 4 : nets[i].in, 3})) {
      const uint32_t o = uint32_t(conv.out), in = uint32_t(conv.in);
      tensors.push_back({conv.name + ".weight",
                         {o, in, 3, 3},
                         "oihw",
                         std::vector<uint16_t>(size_t(o) * in * 9, value)});
      tensors.push_back({conv.name + ".bias", {o}, "x", std::vector<uint16_t>(o, value)});
    }
    library += test::makeTzaBlob(tensors) + std::string(100 + i, '\x90');
  }
  return library;
}

fs::path writeTemp(const std::string& name, const std::string& bytes) {
  const fs::path path = fs::temp_directory_path() / (name + std::to_string(::getpid()));
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

// The default-size network written out plainly, as OIDN's model.py runs it:
// upsample, concatenate, convolve. An independent reference for forward().
torch::Tensor plainForward(OidnUNet& net, const torch::Tensor& input) {
  auto params = net->named_parameters();
  auto conv = [&](const std::string& name, const torch::Tensor& x) {
    return torch::conv2d(x, params[name + ".weight"], params[name + ".bias"], 1, 1).relu();
  };
  auto pool = [](const torch::Tensor& x) { return torch::max_pool2d(x, 2, 2); };
  auto upCat = [](const torch::Tensor& x, const torch::Tensor& skip) {
    return torch::cat({torch::upsample_nearest2d(x, {x.size(2) * 2, x.size(3) * 2}), skip}, 1);
  };
  auto pool1 = pool(conv("enc_conv1", conv("enc_conv0", input)));
  auto pool2 = pool(conv("enc_conv2", pool1));
  auto pool3 = pool(conv("enc_conv3", pool2));
  auto pool4 = pool(conv("enc_conv4", pool3));
  auto x = conv("enc_conv5b", conv("enc_conv5a", pool4));
  x = conv("dec_conv4b", conv("dec_conv4a", upCat(x, pool3)));
  x = conv("dec_conv3b", conv("dec_conv3a", upCat(x, pool2)));
  x = conv("dec_conv2b", conv("dec_conv2a", upCat(x, pool1)));
  return conv("dec_conv0", conv("dec_conv1b", conv("dec_conv1a", upCat(x, input))));
}

}  // namespace

TEST_CASE("the folded upsampling computes what upsample, concatenate and convolve compute") {
  torch::manual_seed(3);
  OidnUNet net(OidnUNetConfig{OidnArch::Default, 9, 3});
  for (auto format : {torch::MemoryFormat::Contiguous, torch::MemoryFormat::ChannelsLast}) {
    const auto input = torch::rand({2, 9, 48, 32}).contiguous(format).requires_grad_();
    const auto ours = net->forward(input);
    const auto plain = plainForward(net, input);
    CHECK(torch::allclose(ours, plain, 1e-4, 1e-5));
    // and so are the gradients that a Control Module trains through
    const auto g = torch::randn_like(plain);
    const auto gradOurs = torch::autograd::grad({ours}, {input}, {g})[0];
    const auto gradPlain = torch::autograd::grad({plain}, {input}, {g})[0];
    CHECK(torch::allclose(gradOurs, gradPlain, 1e-4, 1e-5));
  }
}

TEST_CASE("the networks have OIDN's parameter counts") {
  // As counted from OIDN 2.5.1's own weight blobs.
  CHECK(parameterCount(*OidnUNet(OidnUNetConfig{OidnArch::Default, 9, 3})) == 919811);
  CHECK(parameterCount(*OidnUNet(OidnUNetConfig{OidnArch::Small, 9, 3})) == 320035);
  CHECK(parameterCount(*OidnUNet(OidnUNetConfig{OidnArch::Large, 9, 3})) == 3848387);
  CHECK(parameterCount(*OidnUNet(OidnUNetConfig{OidnArch::Default, 3, 3})) == 914627);
  CHECK(parameterCount(*OidnUNet(OidnUNetConfig{OidnArch::Default, 6, 3})) == 917219);
}

TEST_CASE("the network keeps the size and its output is not negative") {
  OidnUNet net(OidnUNetConfig{OidnArch::Small, 6, 3});
  torch::NoGradGuard noGrad;
  auto y = net->forward(torch::rand({2, 6, 32, 48}));
  CHECK(y.sizes() == torch::IntArrayRef({2, 3, 32, 48}));
  CHECK(y.min().item<float>() >= 0.0f);
}

TEST_CASE("zero residuals leave the network's output unchanged") {
  OidnUNet net(OidnUNetConfig{OidnArch::Default, 9, 3});
  torch::NoGradGuard noGrad;
  const auto x = torch::rand({1, 9, 32, 32});
  ControlResiduals zero;
  const std::vector<int64_t> sizes = {4, 8, 16, 32};
  const auto channels = net->skipChannels();
  for (size_t i = 0; i < channels.size(); ++i)
    zero.skips.push_back(torch::zeros({1, channels[i], sizes[i], sizes[i]}));
  zero.middle = torch::zeros({1, net->bottleneckChannels(), 2, 2});
  CHECK(torch::equal(net->forward(x), net->forward(x, &zero)));
  zero.middle.fill_(1.0f);
  CHECK_FALSE(torch::equal(net->forward(x), net->forward(x, &zero)));
}

TEST_CASE("OIDN's PU transfer function: normalised, monotonic, exactly inverted") {
  CHECK(tonemap::pu(65504.0f) == doctest::Approx(1.0f));
  CHECK(tonemap::pu(0.0f) == 0.0f);
  float previous = -1.0f;
  for (float v : {1e-7f, 1e-6f, 1.6e-6f, 1e-3f, 0.0322f, 0.04f, 0.18f, 1.0f, 100.0f, 60000.0f}) {
    const float t = tonemap::pu(v);
    CHECK(t > previous);
    previous = t;
    CHECK(tonemap::puInverse(t) == doctest::Approx(v).epsilon(1e-4));
  }
}

TEST_CASE("inputs made and outputs decoded with tensor operations agree with the CPU's loops") {
  // The GPU path's oidnInputOnDevice and oidnOutputDecodeOnDevice, run here on
  // the CPU, against the scalar curves: to float rounding, NaN, Inf and
  // negatives included.
  FrameBuffers frame = readFrame(kCrop);
  const float bad[] = {NAN, INFINITY, -1.0f, -INFINITY, 1e30f};
  for (int i = 0; i < 5; ++i) {
    frame.buffers["color"].pixels[size_t(37 * i)] = bad[i];
    frame.buffers["albedo"].pixels[size_t(41 * i + 1)] = bad[i];
    frame.buffers["normal"].pixels[size_t(43 * i + 2)] = bad[i];
  }
  const float exposure = tonemap::oidnExposure(frame.get("color"));
  const TileRect all{0, 0, frame.height, frame.width}, part{5, 7, 40, 50};
  for (const std::string name : {"hdr_alb_nrm", "hdr_calb_cnrm_large", "alb", "nrm"}) {
    CAPTURE(name);
    const OidnInputSet& set = oidnInputSet(name);
    for (const TileRect& r : {all, part}) {
      const torch::Tensor expected = oidnInput(frame, set, exposure, r);
      const torch::Tensor made = oidnInputOnDevice(frame, set, exposure, r, torch::kCPU);
      CHECK(made.sizes() == expected.sizes());
      CHECK(torch::allclose(made, expected, 1e-5, 1e-7));
      // Buffers a previous network left on the device are taken as they are.
      DeviceBuffers onDevice;
      for (const char* name : {"albedo", "normal"})
        onDevice[name] = imageToTensor(frame.get(name)).squeeze(0);
      FrameBuffers colourOnly = frame;
      colourOnly.buffers.erase("albedo");
      colourOnly.buffers.erase("normal");
      if (set.denoised() == "color")
        CHECK(torch::equal(oidnInputOnDevice(colourOnly, set, exposure, r, torch::kCPU, onDevice),
                           made));
    }
    // Outputs past the encoded range's ends, and NaN.
    torch::Tensor output = torch::rand({1, 3, 24, 24}) * 1.2 - 0.1;
    output[0][0][0][0] = NAN;
    const torch::Tensor expected = oidnOutputDecode(output.clone(), set, exposure);  // in place
    const torch::Tensor decoded = oidnOutputDecodeOnDevice(output, set, exposure);
    CHECK(torch::allclose(decoded, expected, 1e-5, 1e-7));
  }
}

TEST_CASE("OIDN's autoexposure maps the mean luminance of bins to 0.18") {
  Image grey(40, 24, 3, 0.5f);
  CHECK(tonemap::oidnExposure(grey) == doctest::Approx(0.36f));
  // Half the bins dark (left out), half at luminance 2: exposure 0.09.
  Image halves(32, 16, 3, 0.0f);
  for (int y = 0; y < 16; ++y)
    for (int x = 16; x < 32; ++x)
      for (int c = 0; c < 3; ++c) halves.at(x, y, c) = 2.0f;
  CHECK(tonemap::oidnExposure(halves) == doctest::Approx(0.09f));
  // Two bins at 1 and 4: the geometric mean is 2.
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x)
      for (int c = 0; c < 3; ++c) halves.at(x, y, c) = 8.0f;
  CHECK(tonemap::oidnExposure(halves) == doctest::Approx(0.18f / 4.0f));
  CHECK(tonemap::oidnExposure(Image(8, 8, 3, 0.0f)) == 1.0f);
  Image withNan(16, 16, 3, 1.0f);
  withNan.at(3, 3, 0) = NAN;
  CHECK(std::isfinite(tonemap::oidnExposure(withNan)));
}

TEST_CASE("a library's blobs are named by their order and shapes") {
  const fs::path lib = writeTemp("fake_oidn_core_", fakeOidnLibrary());
  const auto weights = listOidnWeights(lib.string());
  REQUIRE(weights.size() == 23);
  CHECK(weights[0].name == "alb");
  CHECK(weights[6].name == "hdr_alb_nrm");
  CHECK(weights[6].config.in_channels == 9);
  CHECK(weights[10].name == "hdr_calb_cnrm_large");
  CHECK(weights[22].name == "rtlightmap_hdr");
  CHECK(weights[6].sha256.size() == 64);
  CHECK(weights[6].sha256 != weights[8].sha256);

  SUBCASE("import puts each blob into its network") {
    const OidnImport imported = importOidn(lib.string(), OidnArch::Default);
    CHECK(imported.info.oidn.input_sets == std::vector<std::string>{"hdr", "hdr_alb", "hdr_alb_nrm",
                                                                    "hdr_calb_cnrm_large", "alb",
                                                                    "nrm"});
    CHECK(imported.base->canPrefilter());
    CHECK(imported.base->net("hdr_calb_cnrm_large")->config().arch == OidnArch::Large);
    // Blob i holds 1 + i / 1024 everywhere: hdr is blob 2, hdr_alb 4, hdr_alb_nrm 6, ...
    const std::map<std::string, int> blobOf = {{"hdr", 2},         {"hdr_alb", 4},
                                               {"hdr_alb_nrm", 6}, {"hdr_calb_cnrm_large", 10},
                                               {"alb", 0},         {"nrm", 19}};
    for (const auto& [set, index] : blobOf) {
      CAPTURE(set);
      auto w = imported.base->net(set)->named_parameters()["dec_conv1b.bias"];
      CHECK(w.min().item<float>() == doctest::Approx(1.0 + index / 1024.0));
      CHECK(w.max().item<float>() == doctest::Approx(1.0 + index / 1024.0));
      CHECK(imported.info.notes.at(set + ".weights") == set);
      CHECK(imported.info.notes.at(set + ".blob_sha256") == weights[index].sha256);
    }
    CHECK(imported.info.notes.at("source").find("Open Image Denoise") != std::string::npos);
    const OidnImport large = importOidn(lib.string(), OidnArch::Large);
    CHECK(large.info.notes.at("hdr_alb_nrm.weights") == "hdr_calb_cnrm_large");
    CHECK_FALSE(importOidn(lib.string(), OidnArch::Small).base->canPrefilter());
  }
  SUBCASE("a missing or misshapen blob is refused in one line") {
    const fs::path missing = writeTemp("fake_oidn_missing_", fakeOidnLibrary(5));
    CHECK_THROWS_WITH_AS(listOidnWeights(missing.string()),
                         doctest::Contains("holds 22 weight blobs, expected OIDN 2.x's 23"),
                         ModelError);
    const fs::path reshaped = writeTemp("fake_oidn_reshaped_", fakeOidnLibrary(-1, 6));
    CHECK_THROWS_WITH_AS(listOidnWeights(reshaped.string()),
                         doctest::Contains("should be OIDN's 'hdr_alb_nrm' but has"), ModelError);
    fs::remove(missing);
    fs::remove(reshaped);
  }
  CHECK_THROWS_AS(listOidnWeights("/nonexistent/libOpenImageDenoise_core.so"), ModelError);
  fs::remove(lib);
}

TEST_CASE("the base round-trips through a model file") {
  const fs::path lib = writeTemp("fake_oidn_core_rt_", fakeOidnLibrary());
  const OidnImport imported = importOidn(lib.string(), OidnArch::Small);
  const fs::path file = writeTemp("oidn_small_", "");
  saveModelFile(file.string(), imported.info, *imported.base);
  std::ifstream in(file, std::ios::binary);
  std::string head(200, '\0');
  in.read(head.data(), 200);
  CHECK(head.find("base=oidn") != std::string::npos);
  const LoadedModel loaded = loadModelFile(file.string());
  CHECK(loaded.info.base_kind == BaseKind::Oidn);
  CHECK(loaded.info.oidn.arch == OidnArch::Small);
  CHECK(loaded.info.notes == imported.info.notes);
  auto a = imported.base->named_parameters(), b = loaded.oidn->named_parameters();
  REQUIRE(a.size() == b.size());
  for (const auto& item : a) CHECK(torch::equal(item.value(), b[item.key()]));
  fs::remove(lib);
  fs::remove(file);
}

// Measured: 146-148 dB, at most 9e-7 apart (values around 0.04): the same
// network and arithmetic up to the order of floating-point sums.
void checkAgreesWithOidn(const Image& ours, const std::string& layer) {
  const Image expected = readImage(kOidnOut, 3, {layer + ".R", layer + ".G", layer + ".B"});
  const double psnr = reinhardPsnr(ours, expected);
  const double diff = maxAbsDifference(ours, expected);
  MESSAGE(layer << ": " << psnr << " dB, largest difference " << diff);
  CHECK(psnr > 90.0);
  CHECK(diff < 1e-4);
}

TEST_CASE("the shipped base agrees with OIDN on the committed crop") {
  const Denoiser denoiser = Denoiser::fromFile(kModel);
  const FrameBuffers full = readFrame(kCrop);
  DenoiseOptions noisyAux;
  noisyAux.prefilter = false;
  // OIDN picks its network by the buffers it is given; so does the base.
  for (const std::string set : {"hdr", "hdr_alb", "hdr_alb_nrm"}) {
    CAPTURE(set);
    FrameBuffers frame = full;
    if (set == "hdr") frame.buffers.erase("albedo");
    if (set != "hdr_alb_nrm") frame.buffers.erase("normal");
    const DenoiseResult result = denoiser.denoise(frame, noisyAux);
    CHECK(result.buffersUsed == oidnInputSet(set).buffers);
    CHECK_FALSE(result.prefiltered);
    checkAgreesWithOidn(result.color, set);
  }
  CHECK(denoiser.missingBuffers({"albedo", "normal"}) == std::vector<std::string>{"color"});
}

TEST_CASE("the prefilter mode agrees with OIDN's: aux denoised first, then the colour") {
  const LoadedModel model = loadModelFile(kModel);
  REQUIRE(model.oidn->canPrefilter());
  const FrameBuffers frame = readFrame(kCrop);
  for (const std::string set : {"alb", "nrm"}) {
    CAPTURE(set);
    OidnUNet net = model.oidn->net(set);
    const OidnRunResult out = runOidn(net, oidnInputSet(set), frame, {});
    CHECK(out.exposure == 1.0f);  // aux buffers are not exposed
    checkAgreesWithOidn(tensorToImage(out.image), set);
  }
  const Denoiser denoiser = Denoiser::fromFile(kModel);
  const DenoiseResult result = denoiser.denoise(frame, {});
  CHECK(result.prefiltered);  // the default with albedo and normal
  CHECK(result.steps == 3);
  checkAgreesWithOidn(result.color, "prefiltered");
  checkAgreesWithOidn(result.cleanAlbedo, "alb");
  checkAgreesWithOidn(result.cleanNormal, "nrm");

  // Denoised again with the aux it cleaned (a sequence's accumulated render):
  // one network, the default-size one for albedo and normal, on them as given.
  FrameBuffers again = frame;
  again.buffers["albedo"] = result.cleanAlbedo;
  again.buffers["normal"] = result.cleanNormal;
  again.auxPrefiltered = true;
  const DenoiseResult second = denoiser.denoise(again, {});
  CHECK_FALSE(second.prefiltered);
  CHECK(second.steps == 1);
  CHECK(second.buffersUsed == oidnInputSet("hdr_alb_nrm").buffers);
  again.auxPrefiltered = false;
  DenoiseOptions asGiven;
  asGiven.prefilter = false;
  CHECK(second.color.pixels == denoiser.denoise(again, asGiven).color.pixels);
}

TEST_CASE("bfloat16 convolutions stay near OIDN's result, and float is restored bit for bit") {
  const Denoiser denoiser = Denoiser::fromFile(kModel);
  const FrameBuffers frame = readFrame(kCrop);
  const Image expected =
      readImage(kOidnOut, 3, {"prefiltered.R", "prefiltered.G", "prefiltered.B"});
  DenoiseOptions half;
  half.precision = Precision::BFloat16;
  const DenoiseResult rounded = denoiser.denoise(frame, half);
  const double psnr = reinhardPsnr(rounded.color, expected);
  MESSAGE("bfloat16 against OIDN: " << psnr << " dB");
  CHECK(psnr > 55.0);  // bfloat16 keeps 8 bits of mantissa: near, ...
  CHECK(psnr < 90.0);  // ... but not the float result: it did run in bfloat16
  // The float weights were not touched: the next float run is OIDN's again.
  checkAgreesWithOidn(denoiser.denoise(frame, {}).color, "prefiltered");
}

TEST_CASE("tiles agree with the whole frame") {
  const Denoiser denoiser = Denoiser::fromFile(kModel);
  const FrameBuffers frame = readFrame(std::string(DN_TESTDATA) + "/example/scene000201_4spp.exr");
  const DenoiseResult whole = denoiser.denoise(frame, {});
  DenoiseOptions tiled;
  tiled.tile = 160;  // 3 x 3 tiles, far smaller than OIDN's own
  const DenoiseResult parts = denoiser.denoise(frame, tiled);
  CHECK(parts.tileCount == 9);
  CHECK(whole.tileCount == 1);
  const double psnr = reinhardPsnr(parts.color, whole.color);
  MESSAGE("tiled against whole: " << psnr << " dB");
  CHECK(psnr > 45.0);
}
