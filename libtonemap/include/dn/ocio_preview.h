// Display preview through OpenColorIO: scene-linear in, display-referred out.
#pragma once

#include <string>

#include "dn/image.h"

namespace dn::tonemap {

struct PreviewOptions {
  std::string display;    // empty: the config's default display
  std::string view;       // empty: the display's default view
  float exposure = 0.0f;  // stops, applied in scene-linear before the transform
};

// Uses the config named by $OCIO, else a built-in scene-linear -> sRGB config.
// Transforms the first three channels in place; extra channels are untouched.
// Throws std::runtime_error with OpenColorIO's message on a bad config/name.
void ocioPreview(Image& rgb, const PreviewOptions& options = {});

// "display / view" pairs the active config offers, for --help style listings.
std::string ocioDescribeConfig();

}  // namespace dn::tonemap
