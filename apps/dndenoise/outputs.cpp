#include "dndenoise/outputs.h"

#include <fmt/format.h>

#include "dn/io/buffer_io.h"
#include "dn/io/preview_io.h"

namespace dn::dndenoise {

void writeOutputs(const Options& o, const Written& files, const FrameBuffers& frame,
                  const DenoiseResult& result, const std::optional<PassesResult>& passes,
                  const std::optional<tonemap::OcioDisplay>& display) {
  const std::string& output = files.output;
  const OutputKind kind = outputKindFor(output, o.floatOut);
  if (kind == OutputKind::Display) {
    writeDisplayImage(output, result.color, *display);
  } else {
    WriteOptions write = writeOptionsFor(frame);  // its data window and alpha
    // A sun or lamp above half's range (65504) would be written as Inf.
    write.half = !o.floatOut && fitsHalf(result.color);
    if (o.verbose && !o.floatOut && !write.half)
      fmt::print(stderr, "dndenoise: {}: values above the half range, result written as float\n",
                 files.name);
    write.rgbOnly = o.rgbOnly || files.input.empty() || kind == OutputKind::LinearRgb;
    write.layer = layerPrefixOf(frame) + o.layer;
    if (!result.uncertainty.empty() && !write.rgbOnly)
      write.extraLayers[layerPrefixOf(frame) + "uncertainty"] = result.uncertainty;
    if (passes) {  // float, so that the rule holds in the file too
      write.half = false;
      write.extraLayers.insert(passes->layers.begin(), passes->layers.end());
    }
    writeResult(files.input.empty() ? files.name : files.input, output, result.color, write,
                o.inplace);
  }
  if (!files.preview.empty()) writeDisplayImage(files.preview, result.color, *display);
  if (o.verbose)
    fmt::print(stderr, "dndenoise: wrote {}{}\n", output,
               files.preview.empty() ? "" : " and " + files.preview);
}

}  // namespace dn::dndenoise
