#include "dn/diffusion/schedule.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>

namespace dn {
namespace {

constexpr double kMaxBeta = 0.999;  // improved DDPM: keeps the last cosine step finite
constexpr double kCosineOffset = 0.008;

double cosineAlphaBar(double t) {
  const double angle = (t + kCosineOffset) / (1.0 + kCosineOffset) * M_PI / 2.0;
  return std::cos(angle) * std::cos(angle);
}

std::vector<int64_t> identityTimesteps(int64_t n) {
  std::vector<int64_t> steps(n);
  for (int64_t i = 0; i < n; ++i) steps[i] = i;
  return steps;
}

NoiseSchedule scheduleFromBetas(const std::vector<double>& betas) {
  NoiseSchedule schedule;
  schedule.betas = betas;
  double product = 1.0;
  for (double beta : betas) {
    product *= 1.0 - beta;
    schedule.alphas_cumprod.push_back(product);
  }
  schedule.timesteps = identityTimesteps(static_cast<int64_t>(betas.size()));
  return schedule;
}

// DeepFloyd IF's named respacings, as section counts.
const std::map<std::string, std::string>& namedRespacings() {
  static const std::map<std::string, std::string> modes = {
      {"fast27", "10,10,3,2,2"},
      {"smart27", "7,4,2,1,2,4,7"},
      {"smart50", "10,6,4,3,2,2,3,4,6,10"},
      {"super27", "1,1,1,1,1,1,1,2,5,13"},
      {"super40", "2,2,2,2,2,2,3,4,6,15"},
      {"super100", "4,4,6,6,8,8,10,10,14,30"},
  };
  return modes;
}

std::vector<int64_t> parseSectionCounts(const std::string& spec) {
  std::vector<int64_t> counts;
  std::stringstream stream(spec);
  std::string item;
  while (std::getline(stream, item, ',')) {
    size_t used = 0;
    long long value = 0;
    try {
      value = std::stoll(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != item.size() || value <= 0)
      throw std::invalid_argument("bad respacing spec '" + spec + "'");
    counts.push_back(value);
  }
  if (counts.empty()) throw std::invalid_argument("empty respacing spec");
  return counts;
}

// Cuts [0, n) into equal sections; section i takes counts[i] evenly strided steps.
std::vector<int64_t> sectionTimesteps(int64_t n, const std::vector<int64_t>& counts) {
  const int64_t sections = static_cast<int64_t>(counts.size());
  const int64_t size_per = n / sections;
  const int64_t extra = n % sections;
  std::set<int64_t> taken;
  int64_t start = 0;
  for (int64_t i = 0; i < sections; ++i) {
    const int64_t size = size_per + (i < extra ? 1 : 0);
    if (size < counts[i])
      throw std::invalid_argument("cannot take " + std::to_string(counts[i]) +
                                  " steps from a section of " + std::to_string(size));
    const double stride = counts[i] > 1 ? double(size - 1) / double(counts[i] - 1) : 1.0;
    for (int64_t k = 0; k < counts[i]; ++k)
      // Ties to even, as Python's round() in the reference respacing code.
      taken.insert(start + static_cast<int64_t>(std::nearbyint(k * stride)));
    start += size;
  }
  return {taken.begin(), taken.end()};
}

std::vector<int64_t> uniformTimesteps(int64_t n, int64_t count) {
  for (int64_t stride = 1; stride < n; ++stride) {
    std::vector<int64_t> steps;
    for (int64_t t = 0; t < n; t += stride) steps.push_back(t);
    if (static_cast<int64_t>(steps.size()) == count) return steps;
  }
  throw std::invalid_argument("cannot space " + std::to_string(n) + " steps into exactly " +
                              std::to_string(count) + " with an integer stride");
}

torch::Tensor asBroadcast(const torch::Tensor& alpha_bar) {
  return alpha_bar.dim() == 1 ? alpha_bar.view({-1, 1, 1, 1}) : alpha_bar;
}

}  // namespace

NoiseSchedule makeLinearSchedule(int64_t steps, double beta_start, double beta_end) {
  if (steps < 1) throw std::invalid_argument("schedule needs at least one step");
  std::vector<double> betas(steps);
  for (int64_t i = 0; i < steps; ++i)
    betas[i] = steps == 1 ? beta_start
                          : beta_start + (beta_end - beta_start) * double(i) / double(steps - 1);
  return scheduleFromBetas(betas);
}

NoiseSchedule makeSchedule(ScheduleKind kind, int64_t steps) {
  if (steps < 1) throw std::invalid_argument("schedule needs at least one step");
  if (kind == ScheduleKind::Linear) {
    const double scale = 1000.0 / double(steps);  // keeps the endpoints' noise level for any T
    return makeLinearSchedule(steps, scale * 1e-4, scale * 0.02);
  }
  std::vector<double> betas(steps);
  for (int64_t i = 0; i < steps; ++i) {
    const double ratio =
        cosineAlphaBar(double(i + 1) / double(steps)) / cosineAlphaBar(double(i) / double(steps));
    betas[i] = std::min(1.0 - ratio, kMaxBeta);
  }
  return scheduleFromBetas(betas);
}

NoiseSchedule scheduleFromAlphasCumprod(std::vector<double> alphas_cumprod) {
  NoiseSchedule schedule;
  double previous = 1.0;
  for (double alpha_bar : alphas_cumprod) {
    if (!(alpha_bar > 0.0 && alpha_bar <= previous))
      throw std::invalid_argument("alphas_cumprod must be positive and non-increasing");
    schedule.betas.push_back(1.0 - alpha_bar / previous);
    previous = alpha_bar;
  }
  schedule.alphas_cumprod = std::move(alphas_cumprod);
  schedule.timesteps = identityTimesteps(schedule.size());
  return schedule;
}

std::vector<int64_t> respacedTimesteps(int64_t num_timesteps, const std::string& spec) {
  const auto& named = namedRespacings();
  if (auto it = named.find(spec); it != named.end())
    return sectionTimesteps(num_timesteps, parseSectionCounts(it->second));
  if (spec.rfind("ddim", 0) == 0) {
    const auto counts = parseSectionCounts(spec.substr(4));
    if (counts.size() != 1) throw std::invalid_argument("bad respacing spec '" + spec + "'");
    return uniformTimesteps(num_timesteps, counts[0]);
  }
  return sectionTimesteps(num_timesteps, parseSectionCounts(spec));
}

NoiseSchedule respace(const NoiseSchedule& base, const std::vector<int64_t>& timesteps) {
  if (timesteps.empty()) throw std::invalid_argument("respacing keeps no steps");
  NoiseSchedule spaced;
  double previous = 1.0;
  int64_t last = -1;
  for (int64_t t : timesteps) {
    if (t <= last || t >= base.size())
      throw std::invalid_argument("respaced timesteps must be increasing and inside the schedule");
    const double alpha_bar = base.alphas_cumprod[t];
    spaced.betas.push_back(1.0 - alpha_bar / previous);
    spaced.alphas_cumprod.push_back(alpha_bar);
    spaced.timesteps.push_back(base.timesteps[t]);
    previous = alpha_bar;
    last = t;
  }
  return spaced;
}

NoiseSchedule respace(const NoiseSchedule& base, const std::string& spec) {
  return respace(base, respacedTimesteps(base.size(), spec));
}

const char* scheduleKindName(ScheduleKind kind) {
  return kind == ScheduleKind::Linear ? "linear" : "cosine";
}

ScheduleKind scheduleKindFromName(const std::string& name) {
  if (name == "linear") return ScheduleKind::Linear;
  if (name == "cosine") return ScheduleKind::Cosine;
  throw std::invalid_argument("unknown noise schedule '" + name + "' (linear, cosine)");
}

const char* predictionName(Prediction prediction) {
  switch (prediction) {
    case Prediction::Epsilon:
      return "eps";
    case Prediction::V:
      return "v";
    case Prediction::X0:
      return "x0";
  }
  return "?";
}

Prediction predictionFromName(const std::string& name) {
  if (name == "eps" || name == "epsilon") return Prediction::Epsilon;
  if (name == "v") return Prediction::V;
  if (name == "x0") return Prediction::X0;
  throw std::invalid_argument("unknown prediction type '" + name + "' (eps, v, x0)");
}

torch::Tensor alphaBarAt(const NoiseSchedule& schedule, const torch::Tensor& steps) {
  auto table = torch::tensor(schedule.alphas_cumprod, torch::kFloat64);
  return table.index_select(0, steps.to(torch::kLong).cpu()).to(torch::kFloat).view({-1, 1, 1, 1});
}

torch::Tensor modelTimestepsAt(const NoiseSchedule& schedule, const torch::Tensor& steps) {
  auto table = torch::tensor(schedule.timesteps, torch::kLong);
  return table.index_select(0, steps.to(torch::kLong).cpu()).to(torch::kFloat);
}

torch::Tensor forwardDiffuse(const torch::Tensor& x0, const torch::Tensor& noise,
                             const torch::Tensor& alpha_bar) {
  const auto ab = asBroadcast(alpha_bar);
  return ab.sqrt() * x0 + (1.0 - ab).sqrt() * noise;
}

torch::Tensor x0FromPrediction(Prediction kind, const torch::Tensor& output,
                               const torch::Tensor& z_t, const torch::Tensor& alpha_bar) {
  const auto ab = asBroadcast(alpha_bar);
  switch (kind) {
    case Prediction::Epsilon:
      return (z_t - (1.0 - ab).sqrt() * output) / ab.sqrt();
    case Prediction::V:
      return ab.sqrt() * z_t - (1.0 - ab).sqrt() * output;
    case Prediction::X0:
      return output;
  }
  throw std::invalid_argument("unknown prediction type");
}

torch::Tensor epsFromPrediction(Prediction kind, const torch::Tensor& output,
                                const torch::Tensor& z_t, const torch::Tensor& alpha_bar) {
  const auto ab = asBroadcast(alpha_bar);
  switch (kind) {
    case Prediction::Epsilon:
      return output;
    case Prediction::V:
      return (1.0 - ab).sqrt() * z_t + ab.sqrt() * output;
    case Prediction::X0:
      return (z_t - ab.sqrt() * output) / (1.0 - ab).sqrt();
  }
  throw std::invalid_argument("unknown prediction type");
}

torch::Tensor predictionTarget(Prediction kind, const torch::Tensor& x0, const torch::Tensor& eps,
                               const torch::Tensor& alpha_bar) {
  const auto ab = asBroadcast(alpha_bar);
  switch (kind) {
    case Prediction::Epsilon:
      return eps;
    case Prediction::V:
      return ab.sqrt() * eps - (1.0 - ab).sqrt() * x0;
    case Prediction::X0:
      return x0;
  }
  throw std::invalid_argument("unknown prediction type");
}

}  // namespace dn
