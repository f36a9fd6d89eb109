// The temporal filter's trust learned from data: a small network that, per
// pixel of a reprojected neighbour, scales the weight the hand-set tests gave
// it, from what they look at and more (experiments/temporal_trust/).
#pragma once

#include <string>
#include <vector>

namespace dn::temporal {

// What the network sees of one neighbour at one pixel, in this order (all
// differences in the frame's tonemapped space, relative to its local noise):
enum TrustFeature {
  kGuideTrust,        // the reprojection's trust from the guides, [0, 1]
  kOwnDifference,     // log1p |neighbour's result - the frame's|
  kOwnDifferenceBox,  // the same, averaged over 3x3 pixels
  kMeanDifference,    // log1p |neighbour's result - the mean of all brought in|
  kLightChange,       // log1p of the renders' box test (standard errors); 0 where relit
  kMotion,            // log1p of the pixels the surface moved on screen
  kDistance,          // frames away / 4
  kNoiseLevel,        // log of the frame's local noise level
  kSpread,            // the neighbour's robust spread over the frame (at most 3)
  kRelit,             // 1 where the neighbour was brought to the frame's light first
  kBrightness,        // the frame's result, tonemapped, mean over channels
  kFuture,            // 1 for a later frame
  kTrustFeatureCount
};

// A multilayer perceptron: ReLU between layers, a logistic output in [0, 1].
class LearnedTrust {
 public:
  LearnedTrust() = default;
  // `sizes`: the layers' widths, the features first and 1 last; `params`: per
  // layer, its weights (output-major) then its biases. Throws
  // std::invalid_argument when they do not fit.
  LearnedTrust(std::vector<int> sizes, std::vector<float> params);

  // "12 16 8 1 : p0 p1 ...", one line (a model file's metadata value).
  static LearnedTrust fromText(const std::string& text);
  // The text of file `path`; std::invalid_argument names the file.
  static LearnedTrust fromFile(const std::string& path);
  std::string toText() const;

  bool empty() const { return sizes_.empty(); }
  // The weight of one pixel of one neighbour from its kTrustFeatureCount features.
  float weigh(const float* features) const;
  // The layers' widths and parameters as the constructor takes them (for
  // weighing every pixel at once on a device: dn/temporal/device_filter.h).
  const std::vector<int>& sizes() const { return sizes_; }
  const std::vector<float>& params() const { return params_; }

 private:
  std::vector<int> sizes_;
  std::vector<float> params_;
  int widest_ = 0;
};

}  // namespace dn::temporal
