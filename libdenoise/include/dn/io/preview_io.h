// Display-referred outputs: the denoised colour through an OpenColorIO
// display/view transform, for formats that cannot hold layers or linear light
// (PNG, JPEG, 8/16-bit TIFF) and for --preview images beside the EXR.
#pragma once

#include <string>

#include "dn/image.h"
#include "dn/ocio_preview.h"

namespace dn {

// What an output file can hold, from its extension:
//   Layered    EXR: every layer of the input plus the result, in linear light
//   LinearRgb  PFM, HDR, and TIFF when float is asked for: the result alone, linear
//   Display    everything else (PNG, JPEG, TIFF, ...): a display-referred picture
enum class OutputKind { Layered, LinearRgb, Display };
OutputKind outputKindFor(const std::string& path, bool floatRequested = false);

// Writes the first three channels of the scene-linear `linear` through
// `display`, atomically: 16 bits per channel for TIFF, 8 for other formats.
void writeDisplayImage(const std::string& path, const Image& linear,
                       const tonemap::OcioDisplay& display);

}  // namespace dn
