// Model files and training checkpoints: round trips, every corruption path, and
// exact resumption of training.
#include "doctest_torch.h"
#include "tiny_models.h"

#include <ATen/CPUGeneratorImpl.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include <unistd.h>

#include "dn/diffusion/sampler.h"
#include "dn/nn/model_file.h"
#include "dn/train/trainer.h"

using namespace dn;
namespace fs = std::filesystem;

namespace {

ModelInfo tinyInfo(bool with_control) {
  ModelInfo info;
  info.base = tinyUNetConfig();
  info.has_control = with_control;
  info.control = ControlConfig{4, 3, 8, 2};
  info.input_buffers = {"albedo", "depth"};
  info.prediction = Prediction::V;
  info.respacing = "super27";
  info.notes["spp"] = "4";
  return info;
}

fs::path tempDir() {
  auto dir = fs::temp_directory_path() / ("dn_test_model_file_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  return dir;
}

std::string readBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

void writeBytes(const fs::path& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

// Loading must throw ModelError with one line that names the file and contains `what`.
void checkLoadFails(const fs::path& path, const std::string& what) {
  try {
    loadModelFile(path.string());
    FAIL("loading " << path << " did not throw");
  } catch (const ModelError& error) {
    const std::string message = error.what();
    CAPTURE(message);
    CHECK(message.find(path.string()) != std::string::npos);
    CHECK(message.find(what) != std::string::npos);
    CHECK(message.find('\n') == std::string::npos);
  }
}

TrainBatch tinyBatch(uint64_t seed, int64_t aux_channels) {
  auto generator = at::detail::createCPUGenerator(seed);
  TrainBatch batch;
  batch.target = torch::rand({2, 3, 8, 8}, generator, torch::kFloat);
  batch.noisy =
      (batch.target + 0.2 * torch::randn({2, 3, 8, 8}, generator, torch::kFloat)).clamp(0, 1);
  if (aux_channels > 0) batch.aux = torch::rand({2, aux_channels, 8, 8}, generator, torch::kFloat);
  return batch;
}

std::vector<torch::Tensor> snapshot(const torch::nn::Module& module) {
  std::vector<torch::Tensor> values;
  for (const auto& parameter : module.parameters()) values.push_back(parameter.detach().clone());
  return values;
}

}  // namespace

TEST_CASE("model file round trip keeps metadata and weights") {
  const auto dir = tempDir();
  const auto path = dir / "model.dnm";
  auto info = tinyInfo(true);
  auto model = buildDenoiser(info);
  randomize(*model, 1, 0.1);
  saveModelFile(path.string(), info, *model);
  auto loaded = loadModelFile(path.string());
  CHECK(modelInfoToText(loaded.info) == modelInfoToText(info));
  CHECK(loaded.info.input_buffers == info.input_buffers);
  CHECK(loaded.info.prediction == Prediction::V);
  CHECK(loaded.info.notes.at("spp") == "4");
  CHECK(loaded.info.samplingSchedule().size() == 27);
  auto original = model->named_parameters();
  for (const auto& item : loaded.model->named_parameters())
    CHECK(torch::equal(item.value(), original[item.key()]));
  // The loaded controlled model keeps its base frozen.
  REQUIRE(loaded.prior() != nullptr);
  for (const auto& parameter : loaded.prior()->parameters()) CHECK_FALSE(parameter.requires_grad());
  // No temporary files are left behind.
  int64_t files = 0;
  for (const auto& entry : fs::directory_iterator(dir)) files += entry.is_regular_file();
  CHECK(files == 1);
  fs::remove_all(dir);
}

TEST_CASE("wrong, truncated and corrupt model files throw ModelError with one clear line") {
  const auto dir = tempDir();
  const auto good = dir / "good.dnm";
  auto info = tinyInfo(false);
  auto model = buildDenoiser(info);
  saveModelFile(good.string(), info, *model);
  const std::string bytes = readBytes(good);

  checkLoadFails(dir / "missing.dnm", "cannot open");

  const auto garbage = dir / "garbage.dnm";
  writeBytes(garbage, "this is not a model\n\x01\x02");
  checkLoadFails(garbage, "not a model file");

  const auto empty = dir / "empty.dnm";
  writeBytes(empty, "");
  checkLoadFails(empty, "not a model file");

  const auto truncated = dir / "truncated.dnm";
  writeBytes(truncated, bytes.substr(0, bytes.size() - 100));
  checkLoadFails(truncated, "truncated");

  const auto header_only = dir / "header_only.dnm";
  writeBytes(header_only, bytes.substr(0, 40));
  checkLoadFails(header_only, "damaged header");

  const auto flipped = dir / "flipped.dnm";
  std::string corrupt = bytes;
  corrupt[corrupt.size() / 2] ^= 0x5a;
  writeBytes(flipped, corrupt);
  checkLoadFails(flipped, "checksum mismatch");

  const auto newer = dir / "newer.dnm";
  std::string future = bytes;
  future.replace(future.find("version 1\n"), 10, "version 9\n");
  writeBytes(newer, future);
  checkLoadFails(newer, "format version 9 is not supported");

  // A well-formed container with bad metadata.
  torch::serialize::OutputArchive archive;
  model->save(archive);
  const auto bad_meta = dir / "bad_meta.dnm";
  std::string text = modelInfoToText(info);
  text.replace(text.find("base.res_blocks=1"), 17, "base.res_blocks=x");
  writeArchiveFile(bad_meta.string(), "model", text, archive);
  checkLoadFails(bad_meta, "'base.res_blocks' is not an integer");

  const auto bad_curve = dir / "bad_curve.dnm";
  text = modelInfoToText(info);
  text.replace(text.find("tonemap=log"), 11, "tonemap=abc");
  writeArchiveFile(bad_curve.string(), "model", text, archive);
  checkLoadFails(bad_curve, "abc");

  // Metadata that disagrees with the stored weights.
  const auto mismatch = dir / "mismatch.dnm";
  auto wider = info;
  wider.base.base_channels = 16;
  writeArchiveFile(mismatch.string(), "model", modelInfoToText(wider), archive);
  checkLoadFails(mismatch, "weight");

  // A checkpoint is not a model.
  const auto checkpoint = dir / "checkpoint.dnm";
  writeArchiveFile(checkpoint.string(), "checkpoint", text, archive);
  checkLoadFails(checkpoint, "expected a model");
  fs::remove_all(dir);
}

TEST_CASE("a training step on a controlled model changes only the Control Module") {
  auto info = tinyInfo(true);
  auto model = buildDenoiser(info);
  randomize(*model, 2, 0.1);
  auto controlled = std::dynamic_pointer_cast<ControlledDenoiser>(model);
  REQUIRE(controlled);
  auto base_before = snapshot(*controlled->base());
  auto control_before = snapshot(*controlled->control());
  Trainer trainer(model, info, TrainerOptions{});
  auto stats = trainer.step(tinyBatch(1, 4));
  CHECK(stats.step == 1);
  CHECK(std::isfinite(stats.loss));
  auto base_after = snapshot(*controlled->base());
  for (size_t i = 0; i < base_before.size(); ++i)
    CHECK(torch::equal(base_before[i], base_after[i]));
  auto control_after = snapshot(*controlled->control());
  bool changed = false;
  for (size_t i = 0; i < control_before.size(); ++i)
    changed = changed || !torch::equal(control_before[i], control_after[i]);
  CHECK(changed);
}

TEST_CASE("training steps lower the diffusion loss on a fixed batch") {
  auto info = tinyInfo(true);
  auto model = buildDenoiser(info);
  randomize(*model, 6, 0.1);
  TrainerOptions options;
  options.learning_rate = 2e-3;
  Trainer trainer(model, info, options);
  const auto batch = tinyBatch(21, 4);
  // The same noise and timesteps for both evaluations (seed 5).
  const double before = trainer.evaluate(batch, 5);
  for (int i = 0; i < 100; ++i) trainer.step(batch);
  const double after = trainer.evaluate(batch, 5);
  CAPTURE(before);
  CAPTURE(after);
  CHECK(after < 0.95 * before);  // fresh noise every step: slow but steady
}

namespace {

// Knows the clean image: answers the exact noise z_t holds relative to it, and
// records what the loss fed it.
class CleanOracle : public ConditionalDenoiser {
 public:
  CleanOracle(torch::Tensor x0, NoiseSchedule schedule)
      : x0_(std::move(x0)), schedule_(std::move(schedule)) {}
  torch::Tensor forward(const torch::Tensor& z_t, const torch::Tensor& t, const torch::Tensor&,
                        const torch::Tensor&) override {
    z_t_ = z_t.clone();
    steps_ = t.to(torch::kLong);  // the training schedule: model timestep = step
    const auto ab = alphaBarAt(schedule_, steps_);
    return (z_t - ab.sqrt() * x0_) / (1 - ab).sqrt();
  }
  int64_t sizeMultiple() const override { return 1; }
  torch::Tensor z_t_, steps_;

 private:
  torch::Tensor x0_;
  NoiseSchedule schedule_;
};

}  // namespace

TEST_CASE("render-start training: z_t diffuses the render at a step covering its noise") {
  const NoiseSchedule schedule = makeSchedule(ScheduleKind::Cosine);
  TrainBatch batch;
  auto generator = at::detail::createCPUGenerator(3);
  batch.target = torch::rand({4, 3, 32, 32}, generator, torch::kFloat) * 0.5 + 0.25;
  batch.noisy = batch.target + 0.1 * torch::randn({4, 3, 32, 32}, generator, torch::kFloat);
  const auto x0 = modelSpaceFromTonemapped(batch.target);
  const auto render = modelSpaceFromTonemapped(batch.noisy);
  CleanOracle oracle(x0, schedule);

  DiffusionLossOptions options;
  options.max_timestep = 600;
  options.render_start = 1.0;
  // The target is the noise relative to the clean image, which the oracle knows.
  CHECK(diffusionLoss(oracle, schedule, Prediction::Epsilon, batch, generator, options)
            .item<double>() < 1e-8);
  for (int64_t i = 0; i < 4; ++i) {
    const int64_t step = oracle.steps_[i].item<int64_t>();
    const double ab = schedule.alphaBar(step);
    CAPTURE(step);
    CHECK(step < 600);
    // The forward noise covers the render's RMS noise (0.2 in model space)...
    CHECK(std::sqrt((1 - ab) / ab) >= 0.2 * 0.95);
    // ...and what is left after removing the scaled render is that noise alone.
    const auto injected = (oracle.z_t_[i] - std::sqrt(ab) * render[i]) / std::sqrt(1 - ab);
    CHECK(injected.std().item<double>() == doctest::Approx(1.0).epsilon(0.05));
    CHECK(injected.mean().item<double>() == doctest::Approx(0.0).epsilon(0.05));
  }

  // Without render starts, z_t diffuses the clean image, below max_timestep.
  options.render_start = 0.0;
  for (int repeat = 0; repeat < 5; ++repeat) {
    CHECK(diffusionLoss(oracle, schedule, Prediction::Epsilon, batch, generator, options)
              .item<double>() < 1e-8);
    CHECK(oracle.steps_.max().item<int64_t>() < 600);
  }
}

TEST_CASE("regression ablation: L1 on a direct prediction, saved and reloaded as regression") {
  auto info = tinyInfo(true);
  info.objective = Objective::Regression;
  info.prediction = Prediction::X0;
  auto model = buildDenoiser(info);
  randomize(*model, 8, 0.1);
  const auto batch = tinyBatch(22, 4);
  // The loss is the L1 of one network pass on the noisy image, in model space.
  {
    torch::NoGradGuard no_grad;
    auto direct = model->predict(modelSpaceFromTonemapped(batch.noisy), torch::zeros({2}),
                                 modelSpaceFromTonemapped(batch.noisy), batch.aux);
    auto expected = (direct - modelSpaceFromTonemapped(batch.target)).abs().mean().item<double>();
    CHECK(regressionLoss(*model, batch).item<double>() == doctest::Approx(expected).epsilon(1e-6));
  }
  // As dntrain regression does: every weight trains, the prior's too.
  for (auto& parameter : model->parameters()) parameter.set_requires_grad(true);
  TrainerOptions options;
  options.learning_rate = 3e-3;
  Trainer trainer(model, info, options);
  const double before = trainer.evaluate(batch, 5);
  CHECK(trainer.evaluate(batch, 6) == before);  // no noise: seeds do not matter
  for (int i = 0; i < 60; ++i) trainer.step(batch);
  const double after = trainer.evaluate(batch, 5);
  CAPTURE(before);
  CHECK(after < 0.85 * before);

  const auto dir = tempDir();
  const auto path = (dir / "regression.dnm").string();
  saveModelFile(path, info, *model);
  auto loaded = loadModelFile(path);
  CHECK(loaded.info.objective == Objective::Regression);
  CHECK(modelInfoToText(loaded.info) == modelInfoToText(info));
  // Diffusion models do not mention the objective, so older files read the same.
  CHECK(modelInfoToText(tinyInfo(true)).find("objective") == std::string::npos);
  fs::remove_all(dir);
}

TEST_CASE("learning rate halves on schedule") {
  auto info = tinyInfo(false);
  TrainerOptions options;
  options.learning_rate = 1e-3;
  options.halve_every = 2;
  Trainer trainer(buildDenoiser(info), info, options);
  std::vector<double> rates;
  for (int i = 0; i < 5; ++i) rates.push_back(trainer.step(tinyBatch(i, 0)).learning_rate);
  CHECK((rates == std::vector<double>{1e-3, 1e-3, 5e-4, 5e-4, 2.5e-4}));
}

TEST_CASE("a checkpoint resumes training exactly") {
  const auto dir = tempDir();
  const auto path = (dir / "ckpt.dnc").string();
  auto info = tinyInfo(true);
  TrainerOptions options;
  options.seed = 3;
  auto model_a = buildDenoiser(info);
  randomize(*model_a, 4, 0.1);
  Trainer a(model_a, info, options);
  a.step(tinyBatch(10, 4));
  a.step(tinyBatch(11, 4));
  a.saveCheckpoint(path);
  const double loss_a = a.step(tinyBatch(12, 4)).loss;
  a.step(tinyBatch(13, 4));

  options.seed = 99;  // the checkpoint restores the RNG state
  auto model_b = buildDenoiser(info);
  Trainer b(model_b, info, options);
  b.loadCheckpoint(path);
  CHECK(b.stepCount() == 2);
  CHECK(b.step(tinyBatch(12, 4)).loss == loss_a);
  b.step(tinyBatch(13, 4));
  auto params_a = model_a->named_parameters();
  for (const auto& item : model_b->named_parameters())
    CHECK(torch::equal(item.value(), params_a[item.key()]));

  // A checkpoint for another configuration, and a damaged one, are refused.
  auto other = tinyInfo(true);
  other.control.hint_channels = 16;
  Trainer c(buildDenoiser(other), other, options);
  CHECK_THROWS_AS(c.loadCheckpoint(path), ModelError);
  auto renoted = tinyInfo(true);  // notes carry fixed training settings
  renoted.notes["train.batch"] = "16";
  Trainer d(buildDenoiser(renoted), renoted, options);
  CHECK_THROWS_AS(d.loadCheckpoint(path), ModelError);
  std::string bytes = readBytes(path);
  writeBytes(path, bytes.substr(0, bytes.size() / 2));
  CHECK_THROWS_AS(b.loadCheckpoint(path), ModelError);
  fs::remove_all(dir);
}

TEST_CASE("the EMA model file holds the exponential average of the weights") {
  const auto dir = tempDir();
  auto info = tinyInfo(false);
  auto model = buildDenoiser(info);
  randomize(*model, 5, 0.1);
  auto before = model->named_parameters().values();
  std::vector<torch::Tensor> initial;
  for (auto& p : before) initial.push_back(p.detach().clone());
  Trainer trainer(model, info, TrainerOptions{});
  trainer.step(tinyBatch(1, 0));
  const auto path = (dir / "ema.dnm").string();
  trainer.saveEmaModel(path);
  auto loaded = loadModelFile(path);
  const double decay = 2.0 / 11.0;  // warm-up decay after the first step: (1 + 1) / (10 + 1)
  auto current = model->named_parameters().values();
  auto ema = loaded.model->named_parameters().values();
  REQUIRE(ema.size() == current.size());
  double max_error = 0.0;
  for (size_t i = 0; i < ema.size(); ++i) {
    auto expected = decay * initial[i] + (1 - decay) * current[i].detach();
    max_error = std::max(max_error, (ema[i] - expected).abs().max().item<double>());
  }
  CHECK(max_error < 1e-6);
  fs::remove_all(dir);
}
