// Schedules, forward process, parameterisations, respacing and samplers, checked
// against closed forms and oracle models.
#include "doctest_torch.h"

#include <ATen/CPUGeneratorImpl.h>

#include <cmath>
#include <vector>

#include "dn/diffusion/sampler.h"
#include "dn/diffusion/schedule.h"

using namespace dn;

namespace {

double maxAbsDiff(const torch::Tensor& a, const torch::Tensor& b) {
  return (a - b).abs().max().item<double>();
}

// An oracle that knows x0 and answers in the requested parameterisation.
DenoiseFn oracle(const torch::Tensor& x0, const NoiseSchedule& schedule, Prediction prediction) {
  return [=](const torch::Tensor& z, const torch::Tensor& t) {
    // Map model timesteps back to schedule steps to find alpha_bar.
    std::vector<double> ab;
    for (int64_t i = 0; i < t.size(0); ++i) {
      const auto original = static_cast<int64_t>(t[i].item<float>());
      for (int64_t s = 0; s < schedule.size(); ++s)
        if (schedule.timesteps[s] == original) ab.push_back(schedule.alphaBar(s));
    }
    auto alpha_bar = torch::tensor(ab, torch::kFloat).view({-1, 1, 1, 1});
    auto eps = (z - alpha_bar.sqrt() * x0) / (1 - alpha_bar).sqrt();
    return predictionTarget(prediction, x0, eps, alpha_bar);
  };
}

}  // namespace

TEST_CASE("linear schedule: endpoints, and alpha_bar is the cumulative product of 1 - beta") {
  auto schedule = makeSchedule(ScheduleKind::Linear, 1000);
  REQUIRE(schedule.size() == 1000);
  CHECK(schedule.betas.front() == doctest::Approx(1e-4));
  CHECK(schedule.betas.back() == doctest::Approx(0.02));
  double log_product = 0.0;
  for (int64_t i = 0; i < schedule.size(); ++i) {
    log_product += std::log1p(-schedule.betas[i]);
    CHECK(schedule.alphas_cumprod[i] == doctest::Approx(std::exp(log_product)).epsilon(1e-9));
  }
  // Halving the step count doubles the betas, keeping the endpoints' noise.
  auto short_schedule = makeSchedule(ScheduleKind::Linear, 500);
  CHECK(short_schedule.betas.back() == doctest::Approx(0.04));
}

TEST_CASE("cosine schedule matches the closed form alpha_bar(t) = f(t) / f(0)") {
  const int64_t steps = 1000;
  auto schedule = makeSchedule(ScheduleKind::Cosine, steps);
  auto f = [](double t) {
    const double s = 0.008;
    return std::pow(std::cos((t + s) / (1 + s) * M_PI / 2), 2);
  };
  // Betas are clipped to 0.999 only at the very last steps.
  for (int64_t i = 0; i < steps - 5; ++i)
    CHECK(schedule.alphas_cumprod[i] ==
          doctest::Approx(f(double(i + 1) / steps) / f(0.0)).epsilon(1e-9));
  for (double beta : schedule.betas) CHECK(beta <= 0.999);
  CHECK(schedule.alphas_cumprod.back() < 1e-4);
}

TEST_CASE("forward process has mean sqrt(alpha_bar) x0 and variance 1 - alpha_bar") {
  auto schedule = makeSchedule(ScheduleKind::Cosine, 1000);
  const int64_t n = 400000;
  auto generator = at::detail::createCPUGenerator(7);
  for (int64_t step : {10, 500, 900}) {
    const double ab = schedule.alphaBar(step);
    auto x0 = torch::full({1, 1, 1, n}, 0.3);
    auto noise = torch::randn({1, 1, 1, n}, generator, torch::kFloat);
    auto z = forwardDiffuse(x0, noise, alphaBarAt(schedule, torch::tensor({step})));
    const double sigma = std::sqrt(1.0 - ab);
    // Five standard errors of the estimates.
    CHECK(std::abs(z.mean().item<double>() - std::sqrt(ab) * 0.3) <
          5 * sigma / std::sqrt(double(n)));
    CHECK(std::abs(z.var().item<double>() - (1.0 - ab)) <
          5 * (1.0 - ab) * std::sqrt(2.0 / double(n)));
  }
}

TEST_CASE("eps, v and x0 predictions convert into each other exactly") {
  auto generator = at::detail::createCPUGenerator(3);
  auto x0 = torch::rand({4, 3, 5, 5}, generator, torch::kFloat) * 2 - 1;
  auto eps = torch::randn({4, 3, 5, 5}, generator, torch::kFloat);
  auto alpha_bar = torch::tensor({0.999f, 0.6f, 0.2f, 0.01f});
  auto z = forwardDiffuse(x0, eps, alpha_bar);
  for (auto kind : {Prediction::Epsilon, Prediction::V, Prediction::X0}) {
    CAPTURE(predictionName(kind));
    auto output = predictionTarget(kind, x0, eps, alpha_bar);
    CHECK(maxAbsDiff(x0FromPrediction(kind, output, z, alpha_bar), x0) < 1e-4);
    CHECK(maxAbsDiff(epsFromPrediction(kind, output, z, alpha_bar), eps) < 1e-3);
  }
  // v = sqrt(ab) eps - sqrt(1 - ab) x0, written out.
  auto ab = alpha_bar.view({-1, 1, 1, 1});
  auto v = ab.sqrt() * eps - (1 - ab).sqrt() * x0;
  CHECK(maxAbsDiff(predictionTarget(Prediction::V, x0, eps, alpha_bar), v) < 1e-6);
  CHECK(predictionFromName("v") == Prediction::V);
  CHECK_THROWS_AS(predictionFromName("sample"), std::invalid_argument);
}

TEST_CASE("super27 picks DeepFloyd IF's 27 timesteps") {
  const std::vector<int64_t> expected = {0,   100, 200, 300, 400, 500, 600, 700, 799,
                                         800, 825, 850, 874, 899, 900, 908, 916, 925,
                                         933, 941, 950, 958, 966, 974, 982, 991, 999};
  CHECK(respacedTimesteps(1000, "super27") == expected);
  CHECK(respacedTimesteps(1000, "ddim50").size() == 50);
  CHECK(respacedTimesteps(100, "10").size() == 10);
  CHECK_THROWS_AS(respacedTimesteps(1000, "fast"), std::invalid_argument);
  CHECK_THROWS_AS(respacedTimesteps(1000, "2000"), std::invalid_argument);
  CHECK_THROWS_AS(respacedTimesteps(1000, "5,-1"), std::invalid_argument);
}

TEST_CASE("respacing keeps alphas_cumprod at the chosen steps and recomputes betas") {
  auto base = makeSchedule(ScheduleKind::Cosine, 1000);
  auto spaced = respace(base, "super27");
  REQUIRE(spaced.size() == 27);
  double product = 1.0;
  for (int64_t i = 0; i < spaced.size(); ++i) {
    CHECK(spaced.alphas_cumprod[i] == base.alphas_cumprod[spaced.timesteps[i]]);
    product *= 1.0 - spaced.betas[i];
    CHECK(product == doctest::Approx(spaced.alphas_cumprod[i]).epsilon(1e-12));
  }
  // Respacing to every step is the identity.
  auto all = respace(base, "1000");
  CHECK(all.betas.size() == base.betas.size());
  CHECK(all.betas[500] == doctest::Approx(base.betas[500]).epsilon(1e-12));
  CHECK_THROWS_AS(respace(base, std::vector<int64_t>{5, 3}), std::invalid_argument);
}

TEST_CASE("DDPM posterior matches the Gaussian conditioning closed form") {
  auto schedule = respace(makeSchedule(ScheduleKind::Linear, 1000), "super27");
  for (int64_t step : {1, 8, 20, 26}) {
    const double ab = schedule.alphaBar(step), ab_prev = schedule.alphaBarPrev(step);
    const double alpha = ab / ab_prev, beta = 1 - alpha;
    // q(z_{t-1}|x0) = N(sqrt(ab_prev) x0, 1 - ab_prev); q(z_t|z_{t-1}) = N(sqrt(alpha) z_{t-1},
    // beta).
    const double precision = alpha / beta + 1.0 / (1.0 - ab_prev);
    const double variance = 1.0 / precision;
    auto posterior = ddpmPosterior(schedule, step);
    CHECK(posterior.variance == doctest::Approx(variance).epsilon(1e-9));
    CHECK(posterior.zt_coef == doctest::Approx(variance * std::sqrt(alpha) / beta).epsilon(1e-9));
    CHECK(posterior.x0_coef ==
          doctest::Approx(variance * std::sqrt(ab_prev) / (1 - ab_prev)).epsilon(1e-9));
  }
  auto first = ddpmPosterior(schedule, 0);  // the last reverse step returns x0 itself
  CHECK(first.x0_coef == doctest::Approx(1.0));
  CHECK(first.zt_coef == doctest::Approx(0.0));
  CHECK(first.variance == doctest::Approx(0.0));
}

TEST_CASE("DDIM (eta = 0) and DDPM with an oracle model recover x0") {
  auto schedule = respace(makeSchedule(ScheduleKind::Cosine, 1000), "super27");
  auto generator = at::detail::createCPUGenerator(11);
  auto x0 = torch::rand({2, 3, 8, 8}, generator, torch::kFloat) * 1.8 - 0.9;
  for (auto prediction : {Prediction::Epsilon, Prediction::V, Prediction::X0}) {
    CAPTURE(predictionName(prediction));
    SamplerOptions options;
    options.seed = 5;
    options.kind = SamplerKind::Ddim;
    auto ddim = sample(schedule, prediction, oracle(x0, schedule, prediction),
                       torch::zeros_like(x0), options);
    CHECK(maxAbsDiff(ddim, x0) < 1e-5);
    options.kind = SamplerKind::Ddpm;
    auto ddpm = sample(schedule, prediction, oracle(x0, schedule, prediction),
                       torch::zeros_like(x0), options);
    CHECK(maxAbsDiff(ddpm, x0) < 1e-5);
  }
}

TEST_CASE("step skipping starts at step K-1-s from the forward-diffused conditioning image") {
  auto schedule = respace(makeSchedule(ScheduleKind::Cosine, 1000), "super27");
  auto cond = torch::linspace(-1, 1, 48).view({1, 3, 4, 4});
  for (int64_t skip : {0, 18}) {
    CAPTURE(skip);
    std::vector<float> called;
    torch::Tensor first_z;
    DenoiseFn model = [&](const torch::Tensor& z, const torch::Tensor& t) {
      if (called.empty()) first_z = z.clone();
      called.push_back(t[0].item<float>());
      return torch::zeros_like(z);
    };
    std::vector<int64_t> progress;
    SamplerOptions options;
    options.seed = 42;
    options.skip_steps = skip;
    options.progress = [&](int64_t done, int64_t total) {
      CHECK(total == 27 - skip);
      progress.push_back(done);
    };
    sample(schedule, Prediction::Epsilon, model, cond, options);
    REQUIRE(int64_t(called.size()) == 27 - skip);
    CHECK(called.front() == float(schedule.timesteps[26 - skip]));
    CHECK(called.back() == 0.0f);
    CHECK(progress.back() == 27 - skip);
    // The first latent is the forward process applied to cond with the seed's first noise.
    auto generator = at::detail::createCPUGenerator(42);
    auto noise = torch::randn(cond.sizes(), generator, torch::kFloat);
    auto expected =
        skip == 0
            ? noise
            : forwardDiffuse(cond, noise, torch::tensor({float(schedule.alphaBar(26 - skip))}));
    CHECK(maxAbsDiff(first_z, expected) < 1e-6);
  }
  CHECK(startStep(schedule, 18) == 8);
  // Skipping to a start whose noise covers the render's: the chosen start reaches
  // the level, and one more skipped step would not.
  for (double level : {0.05, 0.3, 1.0}) {
    CAPTURE(level);
    const int64_t skip = maxSkipForNoise(schedule, level);
    auto noise_at = [&](int64_t step) {
      return std::sqrt((1 - schedule.alphaBar(step)) / schedule.alphaBar(step));
    };
    CHECK(noise_at(startStep(schedule, skip)) >= level);
    if (skip + 1 < schedule.size()) CHECK(noise_at(startStep(schedule, skip + 1)) < level);
  }
  CHECK(maxSkipForNoise(schedule, 1e6) == 0);
  CHECK_THROWS_AS(startStep(schedule, 27), std::invalid_argument);
}

TEST_CASE("sampling is deterministic given the seed") {
  auto schedule = respace(makeSchedule(ScheduleKind::Cosine, 1000), "ddim10");
  DenoiseFn model = [](const torch::Tensor& z, const torch::Tensor&) { return 0.5 * z; };
  auto cond = torch::zeros({1, 3, 6, 6});
  SamplerOptions options;
  options.seed = 9;
  auto a = sample(schedule, Prediction::Epsilon, model, cond, options);
  auto b = sample(schedule, Prediction::Epsilon, model, cond, options);
  CHECK(maxAbsDiff(a, b) == 0.0);
  options.seed = 10;
  CHECK(maxAbsDiff(a, sample(schedule, Prediction::Epsilon, model, cond, options)) > 1e-3);
  options.kind = SamplerKind::Ddim;
  options.eta = 1.0;
  auto c = sample(schedule, Prediction::Epsilon, model, cond, options);
  CHECK(maxAbsDiff(c, sample(schedule, Prediction::Epsilon, model, cond, options)) == 0.0);
}
