// Network blocks, the UNet prior and the Control Module: shapes, closed forms,
// and the two ControlNet invariants (identity at initialisation, frozen base).
#include "doctest_torch.h"
#include "tiny_models.h"

#include <ATen/CPUGeneratorImpl.h>

#include <cmath>

#include "dn/nn/control_module.h"
#include "dn/nn/nn_blocks.h"
#include "dn/nn/oidn_unet.h"
#include "dn/nn/unet.h"

using namespace dn;

namespace {

struct Inputs {
  torch::Tensor z, t, cond, aux;
};

Inputs randomInputs(int64_t aux_channels, int64_t size = 16) {
  auto generator = at::detail::createCPUGenerator(1);
  Inputs in;
  in.z = torch::randn({2, 3, size, size}, generator, torch::kFloat);
  in.t = torch::tensor({10.0f, 700.0f});
  in.cond = torch::rand({2, 3, size, size}, generator, torch::kFloat) * 2 - 1;
  in.aux = torch::rand({2, aux_channels, size, size}, generator, torch::kFloat);
  return in;
}

double maxAbsDiff(const torch::Tensor& a, const torch::Tensor& b) {
  return (a - b).abs().max().item<double>();
}

}  // namespace

TEST_CASE("sinusoidal timestep embedding matches its closed form") {
  auto embedding = nn::timestepEmbedding(torch::tensor({0.0f, 3.0f}), 8);
  REQUIRE(embedding.sizes() == torch::IntArrayRef({2, 8}));
  for (int64_t i = 0; i < 4; ++i) {
    const double freq = std::exp(-std::log(10000.0) * double(i) / 4.0);
    CHECK(embedding[0][i].item<double>() == doctest::Approx(1.0));
    CHECK(embedding[0][i + 4].item<double>() == doctest::Approx(0.0));
    CHECK(embedding[1][i].item<double>() == doctest::Approx(std::cos(3.0 * freq)).epsilon(1e-5));
    CHECK(embedding[1][i + 4].item<double>() ==
          doctest::Approx(std::sin(3.0 * freq)).epsilon(1e-5));
  }
  CHECK(nn::groupCount(24, 8) == 8);
  CHECK(nn::groupCount(12, 8) == 6);
  CHECK(nn::groupCount(7, 8) == 7);
}

// softmax(Q^T K / sqrt(d)) V per head, written out with plain matrix products.
torch::Tensor referenceAttention(nn::AttentionBlock& block, const torch::Tensor& x, int64_t heads) {
  const int64_t c = x.size(1), n = x.size(2) * x.size(3), d = c / heads;
  // qkv channels: per head, [q (d), k (d), v (d)].
  auto all = block->qkv->forward(block->norm->forward(x)).view({heads, 3 * d, n});
  std::vector<torch::Tensor> outputs;
  for (int64_t h = 0; h < heads; ++h) {
    auto q = all[h].narrow(0, 0, d), k = all[h].narrow(0, d, d), v = all[h].narrow(0, 2 * d, d);
    auto weights = torch::softmax(torch::mm(q.t(), k) / std::sqrt(double(d)), -1);
    outputs.push_back(torch::mm(v, weights.t()));
  }
  return x + block->proj->forward(torch::cat(outputs, 0).view(x.sizes()));
}

TEST_CASE("attention block equals a direct softmax(QK^T / sqrt(d)) V") {
  torch::NoGradGuard no_grad;
  torch::manual_seed(0);
  nn::AttentionBlock block(8, 4, 2);
  randomize(*block, 2, 0.2);
  auto x = torch::randn({1, 8, 3, 5});
  CHECK(maxAbsDiff(block->forward(x), referenceAttention(block, x, 2)) < 1e-5);
  // 4100 tokens: the scores exceed one chunk, so queries are processed in pieces.
  nn::AttentionBlock single_head(8, 8, 2);
  randomize(*single_head, 3, 0.2);
  auto big = torch::randn({1, 8, 41, 100});
  CHECK(maxAbsDiff(single_head->forward(big), referenceAttention(single_head, big, 1)) < 1e-4);
}

TEST_CASE("res block: identity-like at init, embedding changes the output") {
  nn::ResBlock block(8, 8, 16, 4);
  auto x = torch::randn({2, 8, 6, 6});
  CHECK(maxAbsDiff(block->forward(x, torch::randn({2, 16})), x) == 0.0);  // conv2 starts at zero
  randomize(*block, 4, 0.2);
  auto a = block->forward(x, torch::zeros({2, 16}));
  auto b = block->forward(x, torch::ones({2, 16}));
  CHECK(maxAbsDiff(a, b) > 1e-3);
  nn::ResBlock widen(8, 12, 0, 4);  // no embedding, 1x1 skip
  CHECK(widen->forward(x).sizes() == torch::IntArrayRef({2, 12, 6, 6}));
}

TEST_CASE("UNet: shapes, any image size through predict, bad configs rejected") {
  auto config = tinyUNetConfig();
  auto unet = std::make_shared<UNet>(config);
  randomize(*unet, 3, 0.2);
  auto in = randomInputs(0);
  auto out = unet->predict(in.z, in.t, in.cond);
  CHECK(out.sizes() == in.z.sizes());
  CHECK(unet->sizeMultiple() == 2);
  PriorDenoiser denoiser(unet);
  auto odd = denoiser.predict(torch::randn({1, 3, 15, 13}), torch::tensor({5.0f}),
                              torch::randn({1, 3, 15, 13}), {});
  CHECK(odd.sizes() == torch::IntArrayRef({1, 3, 15, 13}));
  // The timestep matters.
  auto other_t = unet->predict(in.z, torch::tensor({500.0f, 20.0f}), in.cond);
  CHECK(maxAbsDiff(out, other_t) > 1e-4);
  auto bad = config;
  bad.attention_levels = {5};
  CHECK_THROWS_AS(UNet{bad}, std::invalid_argument);
  bad = config;
  bad.channel_mults = {};
  CHECK_THROWS_AS(UNet{bad}, std::invalid_argument);
}

TEST_CASE("at initialisation base + control gives exactly the base's output") {
  auto base = std::make_shared<UNet>(tinyUNetConfig());
  randomize(*base, 5, 0.2);
  ControlConfig control_config;
  control_config.aux_channels = 7;
  control_config.hint_channels = 8;
  ControlledDenoiser controlled(base, control_config);
  auto in = randomInputs(7);
  torch::NoGradGuard no_grad;
  auto expected = base->predict(in.z, in.t, in.cond);
  REQUIRE(expected.abs().max().item<double>() > 1e-3);  // a non-trivial base
  auto got = controlled.forward(in.z, in.t, in.cond, in.aux);
  CHECK(maxAbsDiff(got, expected) <= 1e-6);
  // The residual path is live: once the zero convs move, the output moves.
  randomize(*controlled.control(), 6, 0.2);
  CHECK(maxAbsDiff(controlled.forward(in.z, in.t, in.cond, in.aux), expected) > 1e-4);
}

TEST_CASE("the control copy starts with the base encoder's weights") {
  auto base = std::make_shared<UNet>(tinyUNetConfig());
  randomize(*base, 7, 0.2);
  ControlledDenoiser controlled(base, ControlConfig{4, 3, 8, 2});
  auto base_params = base->named_parameters();
  int64_t compared = 0;
  for (const auto& item : controlled.control()->named_parameters()) {
    if (item.key().rfind("encoder.", 0) != 0) continue;
    const auto* original = base_params.find(item.key());
    REQUIRE(original != nullptr);
    CHECK(torch::equal(item.value(), *original));
    CHECK(item.value().data_ptr() != original->data_ptr());  // a copy, not shared
    ++compared;
  }
  CHECK(compared > 10);
}

TEST_CASE("after a backward pass only control parameters have gradients") {
  auto base = std::make_shared<UNet>(tinyUNetConfig());
  randomize(*base, 8, 0.2);
  ControlledDenoiser controlled(base, ControlConfig{5, 3, 8, 2});
  controlled.train();
  CHECK_FALSE(base->is_training());  // the frozen base stays in eval mode
  CHECK(controlled.control()->is_training());
  auto in = randomInputs(5);
  auto loss = controlled.forward(in.z, in.t, in.cond, in.aux).square().mean();
  loss.backward();
  for (const auto& parameter : base->parameters()) {
    CHECK_FALSE(parameter.requires_grad());
    CHECK(!parameter.grad().defined());
  }
  double control_grad = 0.0;
  for (const auto& item : controlled.control()->named_parameters()) {
    CHECK(item.value().requires_grad());
    REQUIRE(item.value().grad().defined());
    control_grad += item.value().grad().abs().sum().item<double>();
  }
  CHECK(control_grad > 0.0);
  CHECK(parameterCount(controlled, true) == parameterCount(*controlled.control()));
}

TEST_CASE("OIDN network: weights changed in place are seen by the next call (no stale copies)") {
  torch::manual_seed(11);
  OidnUNet net(OidnUNetConfig{OidnArch::Small, 9, 3});
  OidnUNet twin(OidnUNetConfig{OidnArch::Small, 9, 3});
  const torch::Tensor x = torch::rand({1, 9, 32, 48});
  torch::NoGradGuard noGrad;
  auto copyWeights = [&] {
    const auto from = net->named_parameters();
    for (auto& p : twin->named_parameters()) p.value().copy_(from[p.key()]);
  };
  copyWeights();
  const torch::Tensor before = net->forward(x);
  CHECK(torch::equal(before, twin->forward(x)));
  // The folded upsampling weights of a decoder level are kept between calls.
  for (auto& p : net->named_parameters())
    if (p.key().rfind("dec_conv", 0) == 0) p.value().mul_(0.5);
  const torch::Tensor after = net->forward(x);
  CHECK_FALSE(torch::equal(before, after));
  copyWeights();
  CHECK(torch::equal(after, twin->forward(x)));  // as if made anew from the halved weights
  // A reduced precision and back: float is the float result bit for bit.
  net->useInnerPrecision(torch::kBFloat16);
  CHECK_FALSE(torch::equal(net->forward(x), after));
  net->useInnerPrecision(torch::kFloat);
  CHECK(torch::equal(net->forward(x), after));
  CHECK_THROWS_AS(net->useInnerPrecision(torch::kDouble), std::invalid_argument);
}
