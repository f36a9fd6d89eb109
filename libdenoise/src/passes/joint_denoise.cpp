#include "dn/passes/joint_denoise.h"

#include <algorithm>
#include <cmath>

#include "dn/infer/denoiser.h"
#include "dn/infer/oidn_pipeline.h"
#include "dn/io/buffer_io.h"
#include "dn/nn/model_file.h"
#include "dn/nn/model_inputs.h"
#include "dn/nn/oidn_control.h"

namespace dn {

namespace {

constexpr char kLargeSet[] = "hdr_calb_cnrm_large";
constexpr char kDefaultSet[] = "hdr_alb_nrm";  // as a sequence's accumulated render takes it
// Below this a colour pass counts as black: its term explains nothing there,
// and none of the beauty's difference is put into its lights.
constexpr float kBlackColor = 1e-6f;
constexpr char kNoPasses[] =
    ": has no light passes to denoise (Cycles: enable the Diffuse, Glossy, Transmission, "
    "Emission, Environment or Volume light passes; Arnold: diffuse_direct, ...)";

bool allZero(const Image& image) {
  return std::all_of(image.pixels.begin(), image.pixels.end(), [](float v) { return v == 0.0f; });
}

// One OIDN network over `buffers` ({"color"|"albedo"|"normal" -> image}).
Image runNetwork(const OidnBase& base, const std::string& setName,
                 const std::map<std::string, Image>& buffers, const OidnRunOptions& run) {
  FrameBuffers input;
  input.width = buffers.begin()->second.width;
  input.height = buffers.begin()->second.height;
  for (const auto& [name, image] : buffers) input.buffers[name] = image;
  OidnUNet net = base->net(setName);
  net->to(run.device);
  return tensorToImage(runOidn(net, oidnInputSet(setName), input, run).image);
}

// A colour pass cleaned by OIDN's albedo network, as its prefilter mode
// cleans the albedo. The network takes [0, 1]; Cycles' colour passes reach 2
// and more where closures add up (Principled's specular), so a pass above 1
// is scaled into range and back.
Image cleanColorPass(const OidnBase& base, const Image& pass, const OidnRunOptions& run) {
  if (allZero(pass)) return pass;
  float peak = 1.0f;
  for (float v : pass.pixels) peak = std::max(peak, v);
  Image scaled = pass;
  for (float& v : scaled.pixels) v /= peak;
  Image out = runNetwork(base, "alb", {{"albedo", scaled}}, run);
  for (float& v : out.pixels) v *= peak;
  return out;
}

// A signed pass (the residual): its positive and negative parts apart.
Image denoiseSigned(const OidnBase& base, const Image& pass, const Image& albedo,
                    const Image& normal, const OidnRunOptions& run) {
  Image positive = pass, negative = pass;
  for (float& v : positive.pixels) v = std::max(v, 0.0f);
  for (float& v : negative.pixels) v = std::max(-v, 0.0f);
  Image out = denoiseLight(base, positive, albedo, normal, run);
  const Image down = denoiseLight(base, negative, albedo, normal, run);
  for (std::size_t i = 0; i < out.pixels.size(); ++i) out.pixels[i] -= down.pixels[i];
  return out;
}

// One part of the beauty: a light pass (times its term's colour) or the residual.
struct Part {
  std::string key;
  const Image* color = nullptr;  // the term's denoised colour pass; nullptr: none
};

std::vector<Part> partsOf(const LightPassLayout& layout, const LightPassImages& denoised) {
  std::vector<Part> parts;
  for (const auto& term : layout.terms)
    for (const auto& light : term.lights)
      parts.push_back({light, term.color.empty() ? nullptr : &denoised.at(term.color)});
  parts.push_back({kResidualPass, nullptr});
  return parts;
}

// |contribution| x its local relative noise, sqrt(mean err^2 / mean c^2) over
// a wide box: a clean part (a visible background) takes little, a noisy one
// in proportion to its size, and the weights are smooth.
Image relativeNoiseWeights(const Part& part, const Image& x, const Image& d,
                           const PassDenoiseOptions& options) {
  Image err(x.width, x.height, 3), energy = err, magnitude = err;
  for (std::size_t i = 0; i < err.pixels.size(); ++i) {
    const float gain = part.color ? part.color->pixels[i] : 1.0f;
    const float e = gain * (x.pixels[i] - d.pixels[i]), c = gain * d.pixels[i];
    err.pixels[i] = e * e;
    energy.pixels[i] = c * c;
    magnitude.pixels[i] = std::abs(c);
  }
  err = boxMean(err, options.noiseRadius);
  energy = boxMean(energy, options.noiseRadius);
  for (std::size_t i = 0; i < err.pixels.size(); ++i)
    magnitude.pixels[i] *= std::sqrt(err.pixels[i] / (energy.pixels[i] + 1e-12f));
  return magnitude;
}

// The part's share weight at each value.
Image shareWeights(const Part& part, const LightPassImages& noisy, const LightPassImages& denoised,
                   const PassDenoiseOptions& options) {
  const Image& x = noisy.at(part.key);
  const Image& d = denoised.at(part.key);
  Image w(x.width, x.height, 3);
  for (std::size_t i = 0; i < w.pixels.size(); ++i) {
    const float gain = part.color ? part.color->pixels[i] : 1.0f;
    const float err = gain * (x.pixels[i] - d.pixels[i]);
    w.pixels[i] = options.share == ShareRule::Magnitude ? std::abs(gain * d.pixels[i]) : err * err;
  }
  if (options.share == ShareRule::Error) w = boxMean(w, options.errorRadius);
  if (options.share == ShareRule::RelativeNoise) w = relativeNoiseWeights(part, x, d, options);
  // No share where the part has no signal: black in the render and denoised,
  // or multiplied by a black colour.
  for (std::size_t i = 0; i < w.pixels.size(); ++i)
    if ((x.pixels[i] == 0 && d.pixels[i] == 0) ||
        (part.color && std::abs(part.color->pixels[i]) < kBlackColor))
      w.pixels[i] = 0;
  return w;
}

// Shares `difference` (beauty units) out over the parts by their weights;
// where no part has weight, the residual takes it all.
void shareDifference(const std::vector<Part>& parts, const Image& difference,
                     const LightPassImages& noisy, LightPassImages& denoised,
                     const PassDenoiseOptions& options) {
  std::vector<Image> weights;
  for (const auto& part : parts) weights.push_back(shareWeights(part, noisy, denoised, options));
  const std::size_t n = difference.pixels.size();
  for (std::size_t i = 0; i < n; ++i) {
    double total = 0;
    for (const auto& w : weights) total += w.pixels[i];
    for (std::size_t p = 0; p < parts.size(); ++p) {
      const bool residual = p + 1 == parts.size();
      const double share = total > 0 ? weights[p].pixels[i] / total : residual ? 1.0 : 0.0;
      if (share == 0) continue;
      const float gain = parts[p].color ? parts[p].color->pixels[i] : 1.0f;
      denoised[parts[p].key].pixels[i] += float(share * difference.pixels[i] / gain);
    }
  }
}

// The residual set to the beauty minus the other parts, so that the rule
// holds to one rounding whatever the sharing did.
void closeResidual(const LightPassLayout& layout, LightPassImages& passes, const Image& beauty) {
  Image& residual = passes[kResidualPass];
  residual = Image(beauty.width, beauty.height, beauty.channels);  // 0: out of the sum
  const Image explained = recombine(layout, passes);
  for (std::size_t i = 0; i < residual.pixels.size(); ++i)
    residual.pixels[i] = beauty.pixels[i] - explained.pixels[i];
}

// Means over the 2r+1 pixels along rows (`alongRows`) or columns, clipped.
Image lineMean(const Image& image, int r, bool alongRows) {
  Image out(image.width, image.height, image.channels);
  const int length = alongRows ? image.width : image.height;
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) {
      const int at = alongRows ? x : y;
      const int first = std::max(0, at - r), last = std::min(length - 1, at + r);
      for (int c = 0; c < image.channels; ++c) {
        double s = 0;
        for (int k = first; k <= last; ++k) s += alongRows ? image.at(k, y, c) : image.at(x, k, c);
        out.at(x, y, c) = float(s / (last - first + 1));
      }
    }
  return out;
}

}  // namespace

Image boxMean(const Image& image, int r) {
  if (r <= 0) return image;
  return lineMean(lineMean(image, r, true), r, false);
}

Image denoiseLight(const OidnBase& base, const Image& light, const Image& albedo,
                   const Image& normal, const OidnRunOptions& run, bool large) {
  if (allZero(light)) return light;
  return runNetwork(base, large ? kLargeSet : kDefaultSet,
                    {{"color", light}, {"albedo", albedo}, {"normal", normal}}, run);
}

LightPassImages denoisePassesApart(const OidnBase& base, const FrameBuffers& frame,
                                   const LightPassLayout& layout, const LightPassImages& noisy,
                                   const PassDenoiseOptions& options) {
  if (!base->canPrefilter())
    throw std::invalid_argument("denoising light passes needs OIDN's prefilter-mode networks");
  const OidnRunOptions& run = options.run;
  useNetworkPrecision(base, options.precision);
  // The guides as OIDN's prefilter mode cleans them (dn/infer/oidn_pipeline.h).
  const FrameBuffers clean = withCleanAux(base, frame, run, run);
  const Image& albedo = clean.get("albedo");
  const Image& normal = clean.get("normal");
  LightPassImages denoised;
  for (const auto& term : layout.terms) {
    const Image* guide = &albedo;
    if (!term.color.empty()) {
      const Image& color = noisy.at(term.color);
      denoised[term.color] = options.colorPasses == ColorPassDenoise::AlbedoNetwork
                                 ? cleanColorPass(base, color, run)
                                 : denoiseLight(base, color, albedo, normal, run);
      if (options.guide == LightPassGuide::TermColor) guide = &denoised[term.color];
    }
    for (const auto& light : term.lights)
      denoised[light] = denoiseLight(base, noisy.at(light), *guide, normal, run);
  }
  if (options.residualAlone)
    denoised[kResidualPass] = denoiseSigned(base, noisy.at(kResidualPass), albedo, normal, run);
  return denoised;
}

DenoisedPasses shareToBeauty(const LightPassLayout& layout, const LightPassImages& noisy,
                             const LightPassImages& apart, const Image& denoisedBeauty,
                             const PassDenoiseOptions& options) {
  DenoisedPasses out;
  out.independent = apart;
  out.passes = apart;
  if (options.share != ShareRule::None) {
    const Image sum = recombine(layout, apart);
    Image difference = denoisedBeauty;
    for (std::size_t i = 0; i < difference.pixels.size(); ++i)
      difference.pixels[i] -= sum.pixels[i];
    shareDifference(partsOf(layout, apart), difference, noisy, out.passes, options);
  }
  closeResidual(layout, out.passes, denoisedBeauty);
  out.maxRelativeError = maxRelativeDifference(recombine(layout, out.passes), denoisedBeauty);
  return out;
}

DenoisedPasses denoiseLightPasses(const OidnBase& base, const FrameBuffers& frame,
                                  const LightPassLayout& layout, const LightPassImages& noisy,
                                  const Image& denoisedBeauty, const PassDenoiseOptions& options) {
  return shareToBeauty(layout, noisy, denoisePassesApart(base, frame, layout, noisy, options),
                       denoisedBeauty, options);
}

std::map<std::string, Image> denoisedPassLayers(const LightPassLayout& layout,
                                                const LightPassImages& passes) {
  std::map<std::string, Image> layers;
  for (const auto& [key, image] : passes)
    layers[layout.viewLayerPrefix + layout.rule->outputPrefix + layout.layerName(key)] = image;
  return layers;
}

LightPassLayout lightPassesOfFile(const std::string& path, const std::string& viewLayer) {
  std::string prefix = viewLayer.empty() ? "" : viewLayer + ".";
  if (viewLayer.empty()) {
    std::vector<std::string> layers = viewLayers(path);
    layers.erase(std::remove(layers.begin(), layers.end(), "Composite"), layers.end());
    if (layers.size() == 1) prefix = layers.front() + ".";
  }
  return findLightPasses(channelNames(path), prefix);
}

void requireLightPasses(const std::string& path, const std::string& viewLayer) {
  if (lightPassesOfFile(path, viewLayer).empty()) throw IoError(path + kNoPasses);
}

PassDenoiseOptions passOptionsFor(const DenoiseOptions& denoise) {
  PassDenoiseOptions options;
  options.run.device = denoise.device;
  options.run.tile = denoise.tile;
  options.run.maxMemoryBytes = denoise.maxMemoryBytes;
  options.precision = denoise.precision;
  options.residualAlone = false;  // ShareRule::None: the sum closes it
  return options;
}

void requirePrefilterNetworks(const OidnBase& base, const std::string& modelPath) {
  if (!base || !base->canPrefilter())
    throw IoError(modelPath +
                  ": denoising light passes needs a model with OIDN's prefilter-mode "
                  "networks (models/default.dnm)");
}

OidnBase oidnBaseOfModel(const std::string& modelPath) {
  LoadedModel model;
  try {
    model = loadModelFile(modelPath);
  } catch (const std::exception& e) {
    throw IoError(e.what());
  }
  OidnBase base = model.oidnControlled ? model.oidnControlled->base() : model.oidn;
  requirePrefilterNetworks(base, modelPath);
  return base;
}

LightPassLayout passLayoutOfFrame(const std::string& path, const FrameBuffers& frame) {
  LightPassLayout layout = findLightPasses(channelNames(path), layerPrefixOf(frame));
  if (layout.empty()) throw IoError(path + kNoPasses);
  if (!frame.has("albedo") || !frame.has("normal"))
    throw IoError(path +
                  ": denoising light passes needs the albedo and normal (Cycles: "
                  "Denoising Data)");
  return layout;
}

PassesResult denoisePassesOfFile(const OidnBase& base, const std::string& path,
                                 const FrameBuffers& frame, const Image& denoisedBeauty,
                                 const PassDenoiseOptions& options) {
  PassesResult result;
  result.layout = passLayoutOfFrame(path, frame);
  const LightPassImages noisy = readLightPasses(path, result.layout, frame);
  result.denoised = denoiseLightPasses(base, frame, result.layout, noisy, denoisedBeauty, options);
  result.layers = denoisedPassLayers(result.layout, result.denoised.passes);
  return result;
}

}  // namespace dn
