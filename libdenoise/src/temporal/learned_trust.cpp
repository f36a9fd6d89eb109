#include "dn/temporal/learned_trust.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace dn::temporal {

LearnedTrust::LearnedTrust(std::vector<int> sizes, std::vector<float> params)
    : sizes_(std::move(sizes)), params_(std::move(params)) {
  if (sizes_.size() < 2 || sizes_.front() != kTrustFeatureCount || sizes_.back() != 1)
    throw std::invalid_argument("learned trust: its layers must run from " +
                                std::to_string(kTrustFeatureCount) + " features to 1 output");
  std::size_t expected = 0;
  for (std::size_t l = 1; l < sizes_.size(); ++l) {
    if (sizes_[l] < 1) throw std::invalid_argument("learned trust: a layer of no width");
    expected += std::size_t(sizes_[l]) * (sizes_[l - 1] + 1);
  }
  if (params_.size() != expected)
    throw std::invalid_argument("learned trust: " + std::to_string(params_.size()) +
                                " parameters where its layers take " + std::to_string(expected));
  widest_ = *std::max_element(sizes_.begin(), sizes_.end());
}

LearnedTrust LearnedTrust::fromText(const std::string& text) {
  std::istringstream in(text);
  std::vector<int> sizes;
  std::vector<float> params;
  std::string word;
  bool colon = false;
  try {
    while (in >> word && !(colon = word == ":")) sizes.push_back(std::stoi(word));
    while (colon && in >> word) params.push_back(std::stof(word));
  } catch (const std::logic_error&) {  // stoi, stof: not a number, or out of range
    throw std::invalid_argument("learned trust: '" + word + "' is not a number");
  }
  if (!colon) throw std::invalid_argument("learned trust: no ':' after the layer sizes");
  return LearnedTrust(std::move(sizes), std::move(params));
}

LearnedTrust LearnedTrust::fromFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  if (!(in && text << in.rdbuf())) throw std::invalid_argument(path + ": cannot be read");
  try {
    return fromText(text.str());
  } catch (const std::exception& e) {
    throw std::invalid_argument(path + ": not a learned trust (" + e.what() + ")");
  }
}

std::string LearnedTrust::toText() const {
  std::string out;
  for (int s : sizes_) out += std::to_string(s) + " ";
  out += ":";
  char buffer[32];
  for (float p : params_) {
    std::snprintf(buffer, sizeof buffer, " %.9g", static_cast<double>(p));
    out += buffer;
  }
  return out;
}

float LearnedTrust::weigh(const float* features) const {
  // Two buffers of the widest layer, on the stack for the usual small sizes.
  constexpr int kStack = 64;
  float stackA[kStack], stackB[kStack];
  std::vector<float> heapA, heapB;
  float *in = stackA, *out = stackB;
  if (widest_ > kStack) {
    heapA.resize(widest_), heapB.resize(widest_);
    in = heapA.data(), out = heapB.data();
  }
  std::copy_n(features, sizes_[0], in);
  const float* p = params_.data();
  for (std::size_t l = 1; l < sizes_.size(); ++l) {
    const int n = sizes_[l - 1], m = sizes_[l];
    const float* bias = p + std::size_t(n) * m;
    for (int j = 0; j < m; ++j) {
      float s = bias[j];
      for (int i = 0; i < n; ++i) s += p[std::size_t(j) * n + i] * in[i];
      out[j] = l + 1 < sizes_.size() ? std::max(s, 0.0f) : s;
    }
    p = bias + m;
    std::swap(in, out);
  }
  return 1.0f / (1.0f + std::exp(-in[0]));
}

}  // namespace dn::temporal
