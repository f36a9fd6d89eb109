#include "dn/ocio_preview.h"

#include <OpenColorIO/OpenColorIO.h>

#include <cmath>
#include <cstdlib>
#include <sstream>
#include <stdexcept>

namespace OCIO = OCIO_NAMESPACE;

namespace dn::tonemap {

namespace {

// Debian's OpenColorIO 2.1 has no built-in configs (they arrived in 2.2), so
// without $OCIO we use this minimal one: scene-linear Rec.709 to an sRGB display.
constexpr const char* kDefaultConfig = R"(ocio_profile_version: 2
roles:
  default: lin_rec709
  scene_linear: lin_rec709
  data: raw
displays:
  sRGB:
    - !<View> {name: Standard, colorspace: sRGB}
    - !<View> {name: Raw, colorspace: raw}
active_displays: [sRGB]
active_views: [Standard, Raw]
colorspaces:
  - !<ColorSpace>
    name: lin_rec709
    family: linear
    isdata: false
  - !<ColorSpace>
    name: raw
    isdata: true
  - !<ColorSpace>
    name: sRGB
    from_scene_reference: !<GroupTransform>
      children:
        - !<RangeTransform> {min_in_value: 0, min_out_value: 0, max_in_value: 1, max_out_value: 1}
        - !<ExponentWithLinearTransform> {gamma: 2.4, offset: 0.055, direction: inverse}
)";

OCIO::ConstConfigRcPtr activeConfig() {
  const char* env = std::getenv("OCIO");
  if (env && *env) return OCIO::Config::CreateFromEnv();
  std::istringstream stream(kDefaultConfig);
  return OCIO::Config::CreateFromStream(stream);
}

}  // namespace

void ocioPreview(Image& rgb, const PreviewOptions& options) {
  if (rgb.channels < 3) throw std::runtime_error("OCIO preview needs at least 3 channels");
  try {
    auto config = activeConfig();
    std::string display = options.display.empty() ? config->getDefaultDisplay() : options.display;
    std::string view =
        options.view.empty() ? config->getDefaultView(display.c_str()) : options.view;
    auto transform = OCIO::DisplayViewTransform::Create();
    transform->setSrc(OCIO::ROLE_SCENE_LINEAR);
    transform->setDisplay(display.c_str());
    transform->setView(view.c_str());
    auto cpu = config->getProcessor(transform)->getDefaultCPUProcessor();

    const float gain = std::exp2(options.exposure);
    if (gain != 1.0f)
      for (std::size_t i = 0; i < rgb.pixelCount(); ++i)
        for (int c = 0; c < 3; ++c) rgb.pixels[i * rgb.channels + c] *= gain;

    OCIO::PackedImageDesc desc(rgb.pixels.data(), rgb.width, rgb.height, 3, OCIO::BIT_DEPTH_F32,
                               sizeof(float), sizeof(float) * rgb.channels,
                               sizeof(float) * rgb.channels * rgb.width);
    cpu->apply(desc);
  } catch (const OCIO::Exception& e) {
    throw std::runtime_error(std::string("OpenColorIO: ") + e.what());
  }
}

std::string ocioDescribeConfig() {
  std::string out;
  auto config = activeConfig();
  for (int d = 0; d < config->getNumDisplays(); ++d) {
    const char* display = config->getDisplay(d);
    for (int v = 0; v < config->getNumViews(display); ++v)
      out += std::string(display) + " / " + config->getView(display, v) + "\n";
  }
  return out;
}

}  // namespace dn::tonemap
