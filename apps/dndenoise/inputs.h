// dndenoise's inputs: what to read of each file for the model, --buffers,
// and the --ref reference.
#pragma once

#include <string>
#include <vector>

#include "dn/infer/denoiser.h"
#include "dn/io/buffer_io.h"
#include "dndenoise/options.h"

namespace dn::dndenoise {

// The names in `available` that --buffers allows (all when it is not given).
std::vector<std::string> allowed(const Options& o, std::vector<std::string> available);

// What to read of `input`, from its header: the colour and the buffers the model
// needs (one line naming what it lacks).
ReadOptions readInputHeader(const Options& o, const Denoiser& denoiser, const std::string& input);

// The buffers the model reads of `input` (empty: the separate buffer files),
// and in the same decoding the channel groups `extra` (FrameBuffers::extra);
// `name` names it in messages.
FrameBuffers readInput(const Options& o, const Denoiser& denoiser, const std::string& input,
                       const std::string& name, const ChannelGroups& extra = {});

// The reference of --ref, read before any work; its size must match every input.
Image readReference(const Options& o);
void checkReferenceSize(const Options& o, const Image& ref, const FrameBuffers& frame,
                        const std::string& name);

}  // namespace dn::dndenoise
