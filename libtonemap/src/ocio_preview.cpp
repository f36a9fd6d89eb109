#include "dn/ocio_preview.h"

#include <OpenColorIO/OpenColorIO.h>

#include <cmath>
#include <cstdlib>
#include <sstream>
#include <stdexcept>

#include "dn/builtin_ocio_config.h"

namespace OCIO = OCIO_NAMESPACE;

namespace dn::tonemap {

namespace {

struct ResolvedConfig {
  OCIO::ConstConfigRcPtr config;
  std::string name;  // for messages: the file, or "built-in sRGB"
};

// --ocio FILE, else $OCIO, else the built-in config.
ResolvedConfig resolveConfig(const PreviewOptions& options) {
  const char* env = std::getenv("OCIO");
  const std::string file = !options.config.empty() ? options.config : (env && *env ? env : "");
  try {
    if (!file.empty()) return {OCIO::Config::CreateFromFile(file.c_str()), file};
    std::istringstream stream(kBuiltinOcioConfig);
    return {OCIO::Config::CreateFromStream(stream), "built-in sRGB"};
  } catch (const OCIO::Exception& e) {
    throw std::runtime_error((file.empty() ? std::string("built-in OCIO config") : file) +
                             ": not a usable OpenColorIO config (" + e.what() + ")");
  }
}

std::string joinedViews(const OCIO::Config& config, const char* display) {
  std::string out;
  for (int v = 0; v < config.getNumViews(display); ++v)
    out += (out.empty() ? "" : ", ") + std::string(config.getView(display, v));
  return out;
}

std::string joinedDisplays(const OCIO::Config& config) {
  std::string out;
  for (int d = 0; d < config.getNumDisplays(); ++d)
    out += (out.empty() ? "" : ", ") + std::string(config.getDisplay(d));
  return out;
}

bool hasView(const OCIO::Config& config, const std::string& display, const std::string& view) {
  for (int v = 0; v < config.getNumViews(display.c_str()); ++v)
    if (view == config.getView(display.c_str(), v)) return true;
  return false;
}

}  // namespace

struct OcioDisplay::Impl {
  OCIO::ConstCPUProcessorRcPtr cpu;
  float gain = 1.0f;
  std::string description;
};

OcioDisplay::OcioDisplay(const PreviewOptions& options) : impl_(std::make_unique<Impl>()) {
  const ResolvedConfig resolved = resolveConfig(options);
  const OCIO::Config& config = *resolved.config;
  const std::string display =
      options.display.empty() ? config.getDefaultDisplay() : options.display;
  if (config.getNumViews(display.c_str()) == 0)
    throw std::runtime_error(resolved.name + ": no display '" + display +
                             "' (it has: " + joinedDisplays(config) + ")");
  const std::string view =
      options.view.empty() ? config.getDefaultView(display.c_str()) : options.view;
  if (!hasView(config, display, view))
    throw std::runtime_error(resolved.name + ": display '" + display + "' has no view '" + view +
                             "' (it has: " + joinedViews(config, display.c_str()) + ")");
  const std::string source = options.source.empty() ? OCIO::ROLE_SCENE_LINEAR : options.source;
  if (!config.getColorSpace(source.c_str()))
    throw std::runtime_error(resolved.name + ": no colour space or role '" + source + "'");
  try {
    auto transform = OCIO::DisplayViewTransform::Create();
    transform->setSrc(source.c_str());
    transform->setDisplay(display.c_str());
    transform->setView(view.c_str());
    impl_->cpu = config.getProcessor(transform)->getDefaultCPUProcessor();
  } catch (const OCIO::Exception& e) {
    throw std::runtime_error(resolved.name + ": OpenColorIO: " + e.what());
  }
  impl_->gain = std::exp2(options.exposure);
  impl_->description = display + " / " + view + " (OCIO config " + resolved.name + ")";
}

OcioDisplay::~OcioDisplay() = default;
OcioDisplay::OcioDisplay(OcioDisplay&&) noexcept = default;
OcioDisplay& OcioDisplay::operator=(OcioDisplay&&) noexcept = default;

const std::string& OcioDisplay::description() const { return impl_->description; }

void OcioDisplay::apply(Image& rgb) const {
  if (rgb.channels < 3) throw std::runtime_error("OCIO preview needs at least 3 channels");
  if (impl_->gain != 1.0f)
    for (std::size_t i = 0; i < rgb.pixelCount(); ++i)
      for (int c = 0; c < 3; ++c) rgb.pixels[i * rgb.channels + c] *= impl_->gain;
  OCIO::PackedImageDesc desc(rgb.pixels.data(), rgb.width, rgb.height, 3, OCIO::BIT_DEPTH_F32,
                             sizeof(float), sizeof(float) * rgb.channels,
                             sizeof(float) * rgb.channels * rgb.width);
  try {
    impl_->cpu->apply(desc);
  } catch (const OCIO::Exception& e) {
    throw std::runtime_error(std::string("OpenColorIO: ") + e.what());
  }
}

void ocioPreview(Image& rgb, const PreviewOptions& options) { OcioDisplay(options).apply(rgb); }

std::string ocioDescribeConfig(const PreviewOptions& options) {
  const ResolvedConfig resolved = resolveConfig(options);
  std::string out;
  for (int d = 0; d < resolved.config->getNumDisplays(); ++d) {
    const char* display = resolved.config->getDisplay(d);
    for (int v = 0; v < resolved.config->getNumViews(display); ++v)
      out += std::string(display) + " / " + resolved.config->getView(display, v) + "\n";
  }
  return out;
}

const char* builtinOcioConfig() { return kBuiltinOcioConfig; }

}  // namespace dn::tonemap
