// Denoised light passes (dn/passes): the renderers' rules on the committed
// Cycles renders (Blender 3.4 short names, Blender 5 multi-part full names),
// the residual of a file that lacks passes, and the joint denoising's
// invariants: the passes recombine to the denoised beauty, a pass without
// signal takes none of the difference, and each pass gets closer to the
// reference's same pass.
#include "doctest_torch.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "dn/infer/denoiser.h"
#include "dn/infer/device.h"
#include "dn/infer/oidn_pipeline.h"
#include "dn/io/buffer_io.h"
#include "dn/metrics.h"
#include "dn/passes/joint_denoise.h"
#include "dn/passes/light_passes.h"
#include "dn/passes/sequence_passes.h"

using namespace dn;

namespace {

const std::string kBlender34 =
    std::string(DN_TESTDATA) + "/dataset/test/scene_000304/frame_0/spp4_00.exr";
const std::string kBlender5 = std::string(DN_TESTDATA) + "/renderers/blender5_hdri_4spp.exr";
const std::string kBlender5Ref = std::string(DN_TESTDATA) + "/renderers/blender5_hdri_ref.exr";
const std::string kMitsuba =
    std::string(DN_TESTDATA) + "/renderers/mitsuba_box_matpreview_4spp.exr";
const std::string kModel = std::string(DN_SOURCE_DIR) + "/models/default.dnm";

double meanAbs(const Image& image) {
  double s = 0;
  for (float v : image.pixels) s += std::abs(v);
  return s / double(image.pixels.size());
}

double psnr(const Image& a, const Image& reference) {
  return metrics::compare(reference, a, {"psnr"}).values.at("psnr");
}

std::vector<std::string> without(std::vector<std::string> names, const std::string& layer) {
  names.erase(std::remove_if(names.begin(), names.end(),
                             [&](const std::string& n) { return n.rfind(layer + ".", 0) == 0; }),
              names.end());
  return names;
}

}  // namespace

TEST_CASE("Blender 3.4 short names: Cycles' rule with every term") {
  const LightPassLayout layout = findLightPasses(channelNames(kBlender34), "ViewLayer.");
  REQUIRE(layout.rule != nullptr);
  CHECK(layout.rule->renderer == "Cycles");
  CHECK(layout.formula() ==
        "Combined = (DiffDir + DiffInd) x DiffCol + (GlossDir + GlossInd) x GlossCol + "
        "(TransDir + TransInd) x TransCol + VolumeDir + VolumeInd + Emit + Env + Residual");
  CHECK(layout.notes.empty());
  CHECK(layout.channels.at("diffuse_color") == std::vector<std::string>{"ViewLayer.DiffCol.R",
                                                                        "ViewLayer.DiffCol.G",
                                                                        "ViewLayer.DiffCol.B"});
}

TEST_CASE("Cycles' rule explains a Blender 3.4 render: the residual is rounding") {
  const FrameBuffers frame = readFrame(kBlender34);
  const LightPassLayout layout = findLightPasses(channelNames(kBlender34), layerPrefixOf(frame));
  const LightPassImages passes = readLightPasses(kBlender34, layout, frame);
  // Half-float passes: what they leave unexplained is far below the render.
  CHECK(meanAbs(passes.at(kResidualPass)) < 0.01 * meanAbs(frame.get("color")));
  // Without the multiply, the sum would miss the render by much more.
  LightPassLayout additive = layout;
  for (auto& term : additive.terms) term.color.clear();
  LightPassImages noResidual = passes;
  noResidual.erase(kResidualPass);
  Image wrong = recombine(additive, noResidual);
  for (std::size_t i = 0; i < wrong.pixels.size(); ++i)
    wrong.pixels[i] -= frame.get("color").pixels[i];
  CHECK(meanAbs(wrong) > 0.1 * meanAbs(frame.get("color")));
  // With the residual the rule gives the render back.
  CHECK(maxRelativeDifference(recombine(layout, passes), frame.get("color")) < 1e-5);
}

TEST_CASE("Blender 5 multi-part full names; a pass the file lacks goes to the residual") {
  const auto names = channelNames(kBlender5);
  const LightPassLayout layout = findLightPasses(names, "ViewLayer.");
  REQUIRE(layout.rule != nullptr);
  CHECK(layout.rule->renderer == "Cycles");
  CHECK(layout.formula() ==
        "Combined = (Diffuse Direct + Diffuse Indirect) x Diffuse Color + (Glossy Direct + "
        "Glossy Indirect) x Glossy Color + (Transmission Direct + Transmission Indirect) x "
        "Transmission Color + Residual");
  const FrameBuffers frame = readFrame(kBlender5);
  const LightPassImages all = readLightPasses(kBlender5, layout, frame);
  CHECK(meanAbs(all.at(kResidualPass)) < 0.01 * meanAbs(frame.get("color")));

  // Without Glossy Indirect the residual holds Glossy Indirect x Glossy Color.
  const LightPassLayout lacking =
      findLightPasses(without(names, "ViewLayer.Glossy Indirect"), "ViewLayer.");
  CHECK(lacking.formula() ==
        "Combined = (Diffuse Direct + Diffuse Indirect) x Diffuse Color + Glossy Direct x Glossy "
        "Color + (Transmission Direct + Transmission Indirect) x Transmission Color + Residual");
  const LightPassImages passes = readLightPasses(kBlender5, lacking, frame);
  CHECK(passes.count("glossy_indirect") == 0);
  const Image glossyIndirect =
      readImage(kBlender5, 3,
                {"ViewLayer.Glossy Indirect.R", "ViewLayer.Glossy Indirect.G",
                 "ViewLayer.Glossy Indirect.B"});
  Image expected = all.at(kResidualPass);
  for (std::size_t i = 0; i < expected.pixels.size(); ++i)
    expected.pixels[i] += glossyIndirect.pixels[i] * all.at("glossy_color").pixels[i];
  CHECK(meanAbs(expected) > 0.05 * meanAbs(frame.get("color")));
  CHECK(maxRelativeDifference(passes.at(kResidualPass), expected, 1e-2) < 1e-3);
  CHECK(maxRelativeDifference(recombine(lacking, passes), frame.get("color")) < 1e-5);
}

TEST_CASE("the view-dependent share: glossy and transmitted light over the render's") {
  const FrameBuffers frame = readFrame(kBlender5);
  const LightPassImages passes =
      readLightPasses(kBlender5, findLightPasses(channelNames(kBlender5), "ViewLayer."), frame);
  const Image share = viewDependentShare(kBlender5, frame, 0);
  REQUIRE(share.sameShape(Image(frame.width, frame.height, 1)));
  const Image& color = frame.get("color");
  double largest = 0.0;
  for (std::size_t i = 0; i < share.pixels.size(); ++i) {
    double moving = 0.0, all = 0.0;
    for (int c = 0; c < 3; ++c) {
      for (const char* term : {"glossy", "transmission"})
        for (const char* part : {"_direct", "_indirect"})
          moving += std::max(0.0f, passes.at(std::string(term) + part).pixels[3 * i + c] *
                                       passes.at(std::string(term) + "_color").pixels[3 * i + c]);
      all += std::max(0.0f, color.pixels[3 * i + c]);
    }
    const double expected = all > 0.0 ? std::min(1.0, moving / all) : 0.0;
    CHECK(share.pixels[i] == doctest::Approx(expected).epsilon(1e-5));
    largest = std::max(largest, expected);
  }
  CHECK(largest > 0.5);  // the HDRI's chrome
  // Averaged over a box it stays a share; a file without passes has none.
  for (float v : viewDependentShare(kBlender5, frame).pixels) CHECK((v >= 0.0f && v <= 1.0f));
  CHECK(viewDependentShare(kMitsuba, readFrame(kMitsuba)).empty());
  // Its passes read with the frame's buffers (one decoding of the file) give the same.
  ReadOptions withPasses;
  withPasses.extra = viewDependentChannels(kBlender5, "ViewLayer.");
  CHECK(withPasses.extra.size() == 6);  // glossy and transmission: direct, indirect, colour
  const FrameBuffers read = readFrame(kBlender5, withPasses);
  CHECK(viewDependentShare(kBlender5, read, 0).pixels == share.pixels);
}

TEST_CASE("a light pass without its colour pass is not used, and says so") {
  const auto names = without(channelNames(kBlender34), "ViewLayer.GlossCol");
  const LightPassLayout layout =
      findLightPasses(without(names, "ViewLayer.TransInd"), "ViewLayer.");
  CHECK(layout.formula() ==
        "Combined = (DiffDir + DiffInd) x DiffCol + TransDir x TransCol + VolumeDir + "
        "VolumeInd + Emit + Env + Residual");
  REQUIRE(layout.notes.size() == 2);
  CHECK(layout.notes[0] ==
        "GlossDir is not used: the file has no Glossy Color pass to multiply it");
}

TEST_CASE("Arnold's LPE AOVs add up as they are; no passes, no layout") {
  std::vector<std::string> names = {"R", "G", "B", "A"};
  for (const char* aov : {"diffuse_direct", "diffuse_indirect", "specular_direct", "emission"})
    for (const char* c : {"R", "G", "B"}) names.push_back(std::string(aov) + "." + c);
  const LightPassLayout layout = findLightPasses(names, "");
  REQUIRE(layout.rule != nullptr);
  CHECK(layout.rule->renderer == "Arnold");
  CHECK(layout.formula() ==
        "RGBA = diffuse_direct + diffuse_indirect + specular_direct + emission + residual");
  CHECK(findLightPasses(channelNames(kMitsuba), "").empty());
  CHECK_THROWS_WITH_AS(requireLightPasses(kMitsuba), doctest::Contains("has no light passes"),
                       IoError);
}

TEST_CASE("jointly denoised passes recombine to the beauty, each as good as OIDN alone") {
  const OidnBase base = oidnBaseOfModel(kModel);
  const FrameBuffers frame = readFrame(kBlender5);
  const Denoiser denoiser = Denoiser::fromFile(kModel);
  const Image beauty = denoiser.denoise(frame, DenoiseOptions{}).color;
  const PassesResult result = denoisePassesOfFile(base, kBlender5, frame, beauty);
  CHECK(result.denoised.maxRelativeError < 1e-4);
  CHECK(maxRelativeDifference(recombine(result.layout, result.denoised.passes), beauty) < 1e-4);
  CHECK(result.layers.count("ViewLayer.Denoised Diffuse Direct") == 1);
  CHECK(result.layers.count("ViewLayer.Denoised Residual") == 1);
  CHECK(result.layers.size() == 10);

  // OIDN's prefilter mode on each pass alone, as this library runs it (the
  // light passes as the default denoises them; the colour passes guided).
  const LightPassImages noisy = readLightPasses(kBlender5, result.layout, frame);
  PassDenoiseOptions alone;
  alone.colorPasses = ColorPassDenoise::Guided;
  const LightPassImages oidn = denoisePassesApart(base, frame, result.layout, noisy, alone);
  // Against the reference's same pass: each pass with signal is better than
  // noisy and at least as good as OIDN on it alone.
  const FrameBuffers refFrame = readFrame(kBlender5Ref);
  const LightPassImages reference = readLightPasses(kBlender5Ref, result.layout, refFrame);
  for (const auto& key : result.layout.usedKeys()) {
    if (meanAbs(reference.at(key)) < 1e-3 * meanAbs(refFrame.get("color"))) continue;
    CAPTURE(key);
    const double ours = psnr(result.denoised.passes.at(key), reference.at(key));
    CHECK(ours > psnr(noisy.at(key), reference.at(key)) + 0.5);
    CHECK(ours >= psnr(oidn.at(key), reference.at(key)));
  }
}

// The Blender 5 frame's light passes, as read, and the networks that denoise them.
struct Blender5Passes {
  OidnBase base = oidnBaseOfModel(kModel);
  FrameBuffers frame = readFrame(kBlender5);
  LightPassLayout layout = findLightPasses(channelNames(kBlender5), "ViewLayer.");
  LightPassImages noisy = readLightPasses(kBlender5, layout, frame);

  LightPassImages apart(const PassDenoiseOptions& options) const {
    return denoisePassesApart(base, frame, layout, noisy, options);
  }
};

TEST_CASE(
    "the residual closes the rule; shared, nothing moves when the parts add up, or into black") {
  const Blender5Passes b;
  const auto& [base, frame, layout, noisy] = b;
  PassDenoiseOptions options;
  const LightPassImages apart = b.apart(options);
  // The default: every pass as denoised alone; the residual closes the rule.
  const Image& beauty = frame.get("color");
  const DenoisedPasses byDefault = shareToBeauty(layout, noisy, apart, beauty, options);
  for (const auto& key : layout.usedKeys())
    CHECK(byDefault.passes.at(key).pixels == apart.at(key).pixels);
  CHECK(maxRelativeDifference(recombine(layout, byDefault.passes), beauty) < 1e-4);
  // Shared by magnitude, with nothing to share: the beauty is the sum of the
  // passes denoised apart.
  options.share = ShareRule::Magnitude;
  const Image sum = recombine(layout, apart);
  const DenoisedPasses same = shareToBeauty(layout, noisy, apart, sum, options);
  for (const auto& [key, image] : apart) {
    CAPTURE(key);
    CHECK(maxRelativeDifference(same.passes.at(key), image, 1e-2) < 1e-4);
  }
  // A beauty brighter everywhere: where a pass is black, it stays black; the
  // rule still holds.
  Image brighter = sum;
  for (float& v : brighter.pixels) v += 0.1f;
  const DenoisedPasses lifted = shareToBeauty(layout, noisy, apart, brighter, options);
  std::size_t black = 0;
  for (const auto& key : layout.usedKeys())
    for (std::size_t i = 0; i < brighter.pixels.size(); ++i)
      if (noisy.at(key).pixels[i] == 0 && apart.at(key).pixels[i] == 0) {
        ++black;
        REQUIRE(lifted.passes.at(key).pixels[i] == 0);
      }
  CHECK(black > 0);
  CHECK(maxRelativeDifference(recombine(layout, lifted.passes), brighter) < 1e-4);
  // The difference went into the passes, not only into the residual.
  CHECK(meanAbs(lifted.passes.at("diffuse_direct")) > meanAbs(apart.at("diffuse_direct")));
}

TEST_CASE("the passes run in their own precision, whatever the networks ran in before") {
  const Blender5Passes b;
  PassDenoiseOptions options;
  const LightPassImages inFloat = b.apart(options);
  useNetworkPrecision(b.base, Precision::BFloat16);  // as a sequence's second denoising leaves it
  const LightPassImages again = b.apart(options);
  for (const auto& [key, image] : inFloat) {
    CAPTURE(key);
    CHECK(again.at(key).pixels == image.pixels);
  }
  options.precision = Precision::BFloat16;
  const LightPassImages reduced = b.apart(options);
  CHECK(reduced.at("diffuse_direct").pixels != inFloat.at("diffuse_direct").pixels);
}

TEST_CASE("a sequence's second denoisings in bfloat16 only where the CPU computes it natively") {
  const torch::Device cpu(torch::kCPU), cuda(torch::kCUDA);
  const Precision native = cpuComputesBFloat16() ? Precision::BFloat16 : Precision::Float;
  CHECK(secondDenoisingPrecision(Precision::Float, cpu, false) == native);
  CHECK(secondDenoisingPrecision(Precision::Float, cpu, true) == Precision::Float);
  CHECK(secondDenoisingPrecision(Precision::Float, cuda, false) == Precision::Float);
  CHECK(secondDenoisingPrecision(Precision::Float16, cuda, false) == Precision::Float16);
  CHECK(secondDenoisingPrecision(Precision::BFloat16, cpu, true) == Precision::BFloat16);
}
