#include "dn/io/preview_io.h"

#include <algorithm>
#include <filesystem>
#include <set>
#include <stdexcept>

#include "dn/io/buffer_io.h"

namespace dn {

namespace {

std::string lowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
  return ext;
}

bool isTiff(const std::string& ext) { return ext == ".tif" || ext == ".tiff"; }

}  // namespace

OutputKind outputKindFor(const std::string& path, bool floatRequested) {
  static const std::set<std::string> layered = {".exr", ".sxr", ".mxr"};
  static const std::set<std::string> linear = {".pfm", ".hdr"};
  const std::string ext = lowerExtension(path);
  if (layered.count(ext)) return OutputKind::Layered;
  if (linear.count(ext) || (isTiff(ext) && floatRequested)) return OutputKind::LinearRgb;
  return OutputKind::Display;
}

void writeDisplayImage(const std::string& path, const Image& linear,
                       const tonemap::OcioDisplay& display) {
  if (linear.channels < 3) throw IoError(path + ": a display image needs RGB");
  Image rgb(linear.width, linear.height, 3);
  for (std::size_t i = 0; i < rgb.pixelCount(); ++i)
    std::copy_n(&linear.pixels[i * linear.channels], 3, &rgb.pixels[i * 3]);
  try {
    display.apply(rgb);
  } catch (const std::runtime_error& e) {
    throw IoError(path + ": " + e.what());
  }
  const PixelType type = isTiff(lowerExtension(path)) ? PixelType::UInt16 : PixelType::UInt8;
  writeImage(path, rgb, type, {"R", "G", "B"});
}

}  // namespace dn
