#include "dndenoise/inputs.h"

#include <fmt/format.h>

#include <algorithm>

namespace dn::dndenoise {

namespace {

void checkModelInputs(const Denoiser& denoiser, const std::string& name,
                      const std::vector<std::string>& has) {
  if (denoiser.missingBuffers(has).empty()) return;
  std::string needs, hasList;
  for (const auto& b : denoiser.info().input_buffers) needs += (needs.empty() ? "" : ", ") + b;
  for (const auto& b : has) hasList += (hasList.empty() ? "" : ", ") + b;
  throw IoError(fmt::format(
      "{}: the model needs {}; the file has {} (enable Denoising Data and the light passes, or "
      "map channels with --channels)",
      name, needs, hasList));
}

}  // namespace

// The names in `available` that --buffers allows (all when it is not given).
std::vector<std::string> allowed(const Options& o, std::vector<std::string> available) {
  if (o.buffers.empty()) return available;
  available.erase(std::remove_if(available.begin(), available.end(),
                                 [&](const std::string& b) {
                                   return std::find(o.buffers.begin(), o.buffers.end(), b) ==
                                          o.buffers.end();
                                 }),
                  available.end());
  return available;
}

// What to read of `input`, from its header: the colour and the buffers the model
// needs (one line naming what it lacks).
ReadOptions readInputHeader(const Options& o, const Denoiser& denoiser, const std::string& input) {
  ReadOptions read = o.read;
  const std::vector<std::string> has = allowed(o, availableBuffers(input, read));
  // Without a colour, readFrame says what is wrong.
  if (std::find(has.begin(), has.end(), "color") != has.end()) {
    checkModelInputs(denoiser, input, has);
    read.only = denoiser.buffersToRead(has, o.denoise);
  }
  return read;
}

// Only the buffers the model reads: the file's other layers are copied from it
// when the result is written, and holding them as float would cost 1.5 GB on a
// 4K frame with all of Cycles' passes.
FrameBuffers readInput(const Options& o, const Denoiser& denoiser, const std::string& input,
                       const std::string& name, const ChannelGroups& extra) {
  if (input.empty()) {
    FrameBuffers frame = readSeparateFiles(o.separateFiles);
    for (const auto& b : frame.names())
      if (allowed(o, {b}).empty()) frame.buffers.erase(b);
    checkModelInputs(denoiser, name, frame.names());
    return frame;
  }
  ReadOptions read = readInputHeader(o, denoiser, input);
  read.extra = extra;
  return readFrame(input, read);
}

// The reference of --ref, read before any work; its size must match every input.
Image readReference(const Options& o) {
  Image ref = readImage(o.reference, 3);
  countAndZeroNonFinite(ref);
  return ref;
}

void checkReferenceSize(const Options& o, const Image& ref, const FrameBuffers& frame,
                        const std::string& name) {
  if (ref.width != frame.width || ref.height != frame.height)
    throw IoError(fmt::format("{}: is {}x{} but the reference {} is {}x{}", name, frame.width,
                              frame.height, o.reference, ref.width, ref.height));
}

}  // namespace dn::dndenoise
