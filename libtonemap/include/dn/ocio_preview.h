// Display preview through OpenColorIO: scene-linear in, display-referred out,
// for images that artists open in Krita or Photoshop and for the docs' figures.
#pragma once

#include <memory>
#include <string>

#include "dn/image.h"

namespace dn::tonemap {

struct PreviewOptions {
  std::string config;     // OCIO config file; empty: $OCIO, else the built-in sRGB config
  std::string display;    // empty: the config's default display
  std::string view;       // empty: the display's default view
  std::string source;     // the image's colour space; empty: the config's scene_linear role
  float exposure = 0.0f;  // stops, applied in scene-linear before the transform
};

// One display/view transform, resolved and checked once, applied to many images.
// The built-in config (libtonemap/ocio/srgb.ocio) clamps to [0, 1] and applies
// the sRGB curve, as Blender's "Standard" view does.
class OcioDisplay {
 public:
  // Throws std::runtime_error naming the config, display or view that is wrong
  // (with the names the config does offer).
  explicit OcioDisplay(const PreviewOptions& options = {});
  ~OcioDisplay();
  OcioDisplay(OcioDisplay&&) noexcept;
  OcioDisplay& operator=(OcioDisplay&&) noexcept;

  // Transforms the first three channels in place; extra channels are untouched.
  void apply(Image& rgb) const;

  // "sRGB / Filmic (config /usr/share/.../config.ocio)", for logs.
  const std::string& description() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Convenience for one image: OcioDisplay(options).apply(rgb).
void ocioPreview(Image& rgb, const PreviewOptions& options = {});

// "display / view" lines of the config `options` resolves to, for --list-views.
std::string ocioDescribeConfig(const PreviewOptions& options = {});

// The text of the built-in config, for tools that want to apply the same
// transform (it is also installed as share/diffusion_denoise/ocio/srgb.ocio).
const char* builtinOcioConfig();

}  // namespace dn::tonemap
