// The Control Module over the frozen OIDN base: at initialisation the whole
// model returns exactly the base's output; training moves the control, never
// the base; model files round-trip and refuse mismatches; the inputs built
// from tensors equal OIDN's own; the refinement sampler's algebra.
#include "doctest_torch.h"

#include <filesystem>

#include <unistd.h>

#include "dn/diffusion/refine.h"
#include "dn/infer/control_inputs.h"
#include "dn/infer/denoiser.h"
#include "dn/infer/oidn_filter.h"
#include "dn/io/buffer_io.h"
#include "dn/metrics.h"
#include "dn/nn/model_file.h"
#include "dn/tonemap.h"
#include "dn/train/control_loss.h"
#include "dn/train/trainer.h"

using namespace dn;
namespace fs = std::filesystem;

namespace {

const std::string kCrop = std::string(DN_TESTDATA) + "/oidn/crop.exr";
const std::vector<std::string> kExtras = {"depth", "diffuse_direct", "glossy_color"};

OidnControlConfig controlConfig(bool diffusion) {
  OidnControlConfig c;
  c.extra_buffers = kExtras;
  c.hint_channels = 8;
  c.diffusion = diffusion;
  return c;
}

ModelInfo controlledInfo(bool diffusion) {
  ModelInfo info;
  info.base_kind = BaseKind::Oidn;
  info.oidn.arch = OidnArch::Small;
  info.oidn.input_sets = {"hdr", "hdr_alb_nrm"};
  info.has_control = true;
  info.oidn.control = controlConfig(diffusion);
  if (diffusion) info.oidn.sigmas = {0.05, 0.02};
  return info;
}

OidnControlled makeControlled(bool diffusion) {
  torch::manual_seed(3);
  const ModelInfo info = controlledInfo(diffusion);
  return OidnControlled(OidnBase(info.oidn.arch, info.oidn.input_sets), info.oidn.control);
}

// A batch as the loader gives it: linear colour, albedo + normal + extras, target.
TrainBatch randomBatch(int64_t b, int64_t size) {
  const int64_t extras = controlConfig(false).extraChannels();
  TrainBatch batch;
  batch.target = torch::rand({b, 3, size, size}) * 2;
  batch.noisy = batch.target * (0.5 + torch::rand({b, 3, size, size}));
  batch.aux = torch::cat({torch::rand({b, 3, size, size}), torch::rand({b, 3, size, size}) * 2 - 1,
                          torch::rand({b, extras, size, size}) * 3},
                         1);
  batch.present = torch::ones({b, int64_t(kExtras.size())});
  return batch;
}

torch::Tensor hintFor(const OidnControlConfig& config, const TrainBatch& batch,
                      const torch::Tensor& exposure) {
  const int64_t b = batch.noisy.size(0);
  const torch::Tensor extras = batch.aux.narrow(1, 6, config.extraChannels());
  if (!config.diffusion) return controlHint(config, extras, batch.present, exposure);
  return controlHint(config, extras, batch.present, exposure, torch::rand_like(batch.noisy),
                     torch::full({b}, 0.05));
}

}  // namespace

TEST_CASE("at initialisation the controlled model returns exactly the base's output") {
  for (bool diffusion : {false, true}) {
    CAPTURE(diffusion);
    OidnControlled model = makeControlled(diffusion);
    model->eval();
    torch::NoGradGuard noGrad;
    const TrainBatch batch = randomBatch(2, 32);
    const torch::Tensor exposure = batchExposure(batch.noisy);
    const OidnInputSet set = oidnInputSet("hdr_alb_nrm");  // by value: the name is a temporary
    const torch::Tensor x =
        oidnBaseInput(torch::cat({batch.noisy, batch.aux.narrow(1, 0, 6)}, 1), set, exposure);
    const torch::Tensor base = model->steered()->forward(x);
    const torch::Tensor steered =
        model->forward(x, hintFor(model->control()->config(), batch, exposure));
    CHECK(torch::equal(base, steered));
    CHECK(base.abs().sum().item<double>() > 0);  // a real output, not zeros on both sides
  }
}

TEST_CASE("training moves the Control Module and never the base") {
  for (bool diffusion : {false, true}) {
    CAPTURE(diffusion);
    OidnControlled model = makeControlled(diffusion);
    std::vector<torch::Tensor> baseBefore;
    for (const auto& p : model->base()->parameters()) baseBefore.push_back(p.detach().clone());
    TrainerOptions options;
    options.learning_rate = 1e-3;
    Trainer trainer(model, controlledInfo(diffusion), options);
    const TrainBatch batch = randomBatch(2, 32);
    for (int i = 0; i < 3; ++i) trainer.step(batch);

    size_t i = 0;
    for (const auto& p : model->base()->parameters()) CHECK(torch::equal(p, baseBefore[i++]));
    torch::NoGradGuard noGrad;
    model->eval();
    const torch::Tensor exposure = batchExposure(batch.noisy);
    const torch::Tensor x = oidnBaseInput(torch::cat({batch.noisy, batch.aux.narrow(1, 0, 6)}, 1),
                                          oidnInputSet("hdr_alb_nrm"), exposure);
    const double moved = (model->forward(x, hintFor(model->control()->config(), batch, exposure)) -
                          model->steered()->forward(x))
                             .abs()
                             .max()
                             .item<double>();
    CHECK(moved > 0);
  }
}

TEST_CASE("a controlled model file round-trips and refuses a mismatch") {
  const std::string path =
      fs::temp_directory_path() / ("dn_ctl_" + std::to_string(getpid()) + ".dnm");
  OidnControlled model = makeControlled(true);
  {
    torch::NoGradGuard noGrad;
    for (auto& p : model->control()->parameters()) p.normal_();  // not the zero init
  }
  saveModelFile(path, controlledInfo(true), *model);
  LoadedModel loaded = loadModelFile(path);
  REQUIRE(loaded.oidnControlled);
  CHECK(loaded.info.has_control);
  CHECK(loaded.info.oidn.control.extra_buffers == kExtras);
  CHECK(loaded.info.oidn.control.diffusion);
  CHECK(loaded.info.oidn.sigmas == std::vector<double>{0.05, 0.02});
  const auto a = model->named_parameters(), b = loaded.oidnControlled->named_parameters();
  REQUIRE(a.size() == b.size());
  for (const auto& item : a) CHECK(torch::equal(item.value(), b[item.key()]));

  ModelInfo other = controlledInfo(true);
  other.oidn.control.extra_buffers = {"depth"};  // fewer hint channels than the weights
  std::string text = modelInfoToText(other);
  torch::serialize::OutputArchive archive;
  model->save(archive);
  writeArchiveFile(path, "model", text, archive);
  CHECK_THROWS_AS(loadModelFile(path), ModelError);

  ModelInfo badSet = controlledInfo(false);
  badSet.oidn.input_sets = {"hdr"};
  CHECK_THROWS_AS(modelInfoFromText(modelInfoToText(badSet), "x.dnm"), ModelError);
  fs::remove(path);
}

TEST_CASE("inputs built from tensors equal OIDN's own") {
  const FrameBuffers frame = readFrame(kCrop);
  const OidnInputSet set = oidnInputSet("hdr_alb_nrm");  // by value: the name is a temporary
  const TileRect all{0, 0, frame.height, frame.width};
  const float exposure = tonemap::oidnExposure(frame.get("color"));
  std::vector<torch::Tensor> parts;
  for (const auto& name : set.buffers) parts.push_back(imageToTensor(frame.get(name)));
  const torch::Tensor fromTensors =
      oidnBaseInput(torch::cat(parts, 1), set, torch::tensor({exposure}));
  CHECK(torch::equal(fromTensors, oidnInput(frame, set, exposure, all)));
  CHECK(batchExposure(parts[0]).item<float>() == exposure);
  for (const char* name : {"alb", "nrm"}) {  // the prefilter's networks, unexposed
    CAPTURE(name);
    const OidnInputSet auxSet = oidnInputSet(name);  // by value: the name is a temporary
    CHECK(torch::equal(
        oidnBaseInput(imageToTensor(frame.get(auxSet.denoised())), auxSet, torch::ones({1})),
        oidnInput(frame, auxSet, 1.0f, all)));
  }

  const auto [extras, present] = frameExtras(frame, controlConfig(false), all);
  CHECK(extras.size(1) == controlConfig(false).extraChannels());
  for (size_t i = 0; i < kExtras.size(); ++i)
    CHECK(present[0][int64_t(i)].item<float>() == (frame.has(kExtras[i]) ? 1.0f : 0.0f));
  const torch::Tensor encoded = puEncode(torch::tensor({0.0f, 0.5f, 7.0f, 1000.0f}));
  CHECK(torch::allclose(puDecode(encoded), torch::tensor({0.0f, 0.5f, 7.0f, 1000.0f}), 1e-4, 1e-5));
}

TEST_CASE("refinement: DDIM steps down the noise levels from the base's estimate") {
  const torch::Tensor start = torch::full({1, 3, 4, 4}, 0.25);
  const torch::Tensor noise = torch::randn({1, 3, 4, 4});
  CHECK(torch::equal(refine(start, noise, {}, nullptr), start));
  std::vector<double> seen;
  std::vector<torch::Tensor> states;
  const torch::Tensor target = torch::full({1, 3, 4, 4}, 0.5);
  const torch::Tensor out =
      refine(start, noise, {0.2, 0.1, 0.05}, [&](const torch::Tensor& s, double sigma) {
        seen.push_back(sigma);
        states.push_back(s.clone());
        return target;
      });
  CHECK(seen == std::vector<double>{0.2, 0.1, 0.05});
  CHECK(torch::allclose(states[0], start + 0.2 * noise));
  // With a fixed x0 the implied noise is kept and scaled to each level.
  CHECK(torch::allclose(states[1], target + 0.5 * (states[0] - target)));
  CHECK(torch::allclose(states[2], target + 0.5 * (states[1] - target)));
  CHECK(torch::equal(out, target));
  CHECK_THROWS_AS(checkSigmas({0.1, 0.2}), std::invalid_argument);
  CHECK_THROWS_AS(checkSigmas({0.1, 0.0}), std::invalid_argument);
}

TEST_CASE("dndenoise's path: an untrained Control Module denoises exactly as the base") {
  const std::string path =
      fs::temp_directory_path() / ("dn_ctl_denoise_" + std::to_string(getpid()) + ".dnm");
  LoadedModel base = loadModelFile(std::string(DN_SOURCE_DIR) + "/models/oidn.dnm");
  const FrameBuffers frame = readFrame(kCrop);
  // The network for noisy albedo and normal, and the prefilter mode's, whose
  // guides dndenoise cleans first as the base alone does.
  for (const std::string steer : {"hdr_alb_nrm", "hdr_calb_cnrm_large"}) {
    const bool prefiltered = steer != "hdr_alb_nrm";
    DenoiseOptions options;
    options.prefilter = prefiltered;
    options.lightPaths = false;
    const Image expected = Denoiser(base).denoise(frame, options).color;
    options.control = ControlUse::Always;
    for (bool diffusion : {false, true}) {
      CAPTURE(steer);
      CAPTURE(diffusion);
      ModelInfo info = base.info;
      info.has_control = true;
      info.oidn.control = controlConfig(diffusion);
      info.oidn.control.input_set = steer;
      if (diffusion) info.oidn.sigmas = {0.05, 0.02};
      OidnControlled model(base.oidn, info.oidn.control);
      saveModelFile(path, info, *model);
      const Denoiser denoiser = Denoiser::fromFile(path);
      REQUIRE(denoiser.controlApplies(frame.names()));
      options.samples = 2;
      const DenoiseResult result = denoiser.denoise(frame, options);
      CHECK(result.color.pixels == expected.pixels);
      CHECK(result.prefiltered == prefiltered);
      CHECK(result.steps == (prefiltered ? 2 : 0) + (diffusion ? 3 : 1));
      if (diffusion) {
        REQUIRE(result.uncertainty.pixels.size() > 0);
        CHECK(*std::max_element(result.uncertainty.pixels.begin(),
                                result.uncertainty.pixels.end()) == 0.0f);
      }
    }
  }
  fs::remove(path);
}

TEST_CASE("training's prefilter on tensors equals dndenoise's on the frame") {
  // Both pad the frame alike to the alignment, so they see the same pixels.
  LoadedModel base = loadModelFile(std::string(DN_SOURCE_DIR) + "/models/oidn.dnm");
  base.oidn->eval();
  const FrameBuffers frame = readFrame(kCrop);
  c10::InferenceMode inference;
  const torch::Tensor clean =
      cleanAux(base.oidn, imageToTensor(frame.get("albedo")), imageToTensor(frame.get("normal")));
  const char* sets[] = {"alb", "nrm"};
  for (int i = 0; i < 2; ++i) {
    CAPTURE(sets[i]);
    OidnUNet net = base.oidn->net(sets[i]);
    const torch::Tensor expected = runOidn(net, oidnInputSet(sets[i]), frame, {}).image;
    const torch::Tensor got = clean.narrow(1, 3 * i, 3);
    CHECK(torch::allclose(got, expected, 1e-4, 1e-5));
    CHECK((got - imageToTensor(frame.get(i == 0 ? "albedo" : "normal"))).abs().max().item<float>() >
          0.01f);  // the networks did clean something
  }
}

TEST_CASE("the trained Control Module denoises a splatted render that OIDN leaves noisy") {
  // testdata/renderers: Mitsuba 3's default Gaussian pixel filter correlates the
  // noise of neighbouring pixels; the base (OIDN) gains 0.2 dB on it.
  const std::string dir = std::string(DN_TESTDATA) + "/renderers/";
  const FrameBuffers frame = readFrame(dir + "mitsuba_gauss_cornell_4spp.exr");
  const Image reference = readFrame(dir + "mitsuba_gauss_cornell_ref.exr").get("color");
  auto score = [&](const Image& image) {
    return metrics::compare(reference, image, {"psnr", "flip"}).values;
  };
  const std::string models = std::string(DN_SOURCE_DIR) + "/models/";
  const auto noisy = score(frame.get("color"));
  const auto base = score(Denoiser::fromFile(models + "oidn.dnm").denoise(frame, {}).color);
  const DenoiseResult result =
      Denoiser::fromFile(models + "oidn-control-diffusion.dnm").denoise(frame, {});
  CHECK(result.steered);  // the base left the noise: taken for correlated
  REQUIRE(result.noiseLeft);
  CHECK(result.noiseLeft->fraction() > kCorrelatedNoiseLeft);
  const auto steered = score(result.color);
  MESSAGE("PSNR noisy ", noisy.at("psnr"), ", base ", base.at("psnr"), ", controlled ",
          steered.at("psnr"));
  CHECK(base.at("psnr") - noisy.at("psnr") < 1.0);     // OIDN's failure on splatted noise
  CHECK(steered.at("psnr") - noisy.at("psnr") > 4.0);  // measured 5.3 dB
  CHECK(steered.at("flip") < base.at("flip") - 0.02);  // measured 0.087 against 0.118
}

TEST_CASE("on independent noise the Control Module leaves the base alone, unless told") {
  // The committed renders of Cycles 3.4, Blender 5 and Mitsuba with a box filter.
  const std::string models = std::string(DN_SOURCE_DIR) + "/models/";
  const Denoiser base = Denoiser::fromFile(models + "oidn.dnm");
  const Denoiser controlled = Denoiser::fromFile(models + "oidn-control-diffusion.dnm");
  for (const char* file : {"/example/scene000201_4spp.exr", "/renderers/blender5_hdri_4spp.exr",
                           "/renderers/mitsuba_box_matpreview_4spp.exr"}) {
    CAPTURE(file);
    const FrameBuffers frame = readFrame(std::string(DN_TESTDATA) + file);
    const DenoiseResult result = controlled.denoise(frame, {});
    CHECK_FALSE(result.steered);
    REQUIRE(result.noiseLeft);
    CHECK(result.noiseLeft->fraction() < kCorrelatedNoiseLeft);
    DenoiseOptions same;
    same.prefilter = result.prefiltered;  // as the controlled model's base could
    CHECK(imageToTensor(result.color).equal(imageToTensor(base.denoise(frame, same).color)));
  }
  const FrameBuffers frame = readFrame(std::string(DN_TESTDATA) + "/example/scene000201_4spp.exr");
  DenoiseOptions always;
  always.control = ControlUse::Always;
  always.sigmas = std::vector<double>{};  // one pass is enough to tell
  CHECK(controlled.denoise(frame, always).steered);
  DenoiseOptions never;
  never.control = ControlUse::Never;
  const DenoiseResult alone = controlled.denoise(frame, never);
  CHECK_FALSE(alone.steered);
  CHECK_FALSE(alone.noiseLeft);
}

TEST_CASE("a frame whose noise is known is steered as it says, without measuring it again") {
  // A sequence's accumulated render has its frame's noise (FrameBuffers::correlatedNoise).
  const std::string models = std::string(DN_SOURCE_DIR) + "/models/";
  const Denoiser controlled = Denoiser::fromFile(models + "oidn-control-diffusion.dnm");
  DenoiseOptions options;
  options.sigmas = std::vector<double>{};  // one pass is enough to tell
  FrameBuffers splatted =
      readFrame(std::string(DN_TESTDATA) + "/renderers/mitsuba_gauss_cornell_4spp.exr");
  splatted.correlatedNoise = false;  // the gate would steer: told otherwise
  const DenoiseResult base = controlled.denoise(splatted, options);
  CHECK_FALSE(base.steered);
  CHECK_FALSE(base.noiseLeft);
  FrameBuffers independent = readFrame(std::string(DN_TESTDATA) + "/example/scene000201_4spp.exr");
  independent.correlatedNoise = true;  // the gate would not
  const DenoiseResult steered = controlled.denoise(independent, options);
  CHECK(steered.steered);
  CHECK_FALSE(steered.noiseLeft);
}
