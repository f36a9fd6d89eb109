// Reading render buffers from multilayer EXR (Blender/Cycles and common
// renderer naming) or from one file per buffer, and writing results atomically.
#pragma once

#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "dn/image.h"
#include "dn/io/buffers.h"

namespace dn {

// Every I/O failure: the message is one line, "<file>: <what is wrong>".
class IoError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Groups of named channels by a caller's name.
using ChannelGroups = std::map<std::string, std::vector<std::string>>;

struct ReadOptions {
  // Explicit channel lists per canonical buffer, e.g.
  // {"albedo", {"diffuse.R", "diffuse.G", "diffuse.B"}}; they win over name lookup.
  std::map<std::string, std::vector<std::string>> overrides;
  // Buffers to load; empty loads every canonical buffer the file has.
  std::vector<std::string> only;
  // The view layer of a multilayer file to read, e.g. "ViewLayer.001" (names
  // may hold dots and spaces). "": the file's only one; with several (Blender's
  // "Composite" aside) reading fails with a line that lists them.
  std::string viewLayer;
  // Channel groups read in the same decoding as the buffers, by the caller's
  // name, into FrameBuffers::extra: what it needs beside the buffers (motion
  // vectors, light passes) without decompressing the file again.
  ChannelGroups extra;
};

// The view layers of a multilayer file, sorted: the prefixes in front
// of a colour pass ("ViewLayer" of "ViewLayer.Combined.R"). Empty for files
// without view layers.
std::vector<std::string> viewLayers(const std::string& path);

// Parses "albedo=diffuse.R,diffuse.G,diffuse.B" into an override entry.
std::pair<std::string, std::vector<std::string>> parseChannelOverride(const std::string& text);

// One frame from a single (usually multilayer) image file. "color" is required.
// Any file OpenImageIO reads: scanline or tiled, MIP-mapped (level 0 is read),
// any compression, half or float, single- or multi-part. Buffers are read in
// the colour's data window; parts with another data window are placed by
// pixel coordinates (zeros outside them), parts with another display window
// are another image (a preview) and are not used.
FrameBuffers readFrame(const std::string& path, const ReadOptions& options = {});

// The canonical buffers readFrame would find in the file (options.only aside),
// in canonical order, from the header alone: no pixels are read.
std::vector<std::string> availableBuffers(const std::string& path, const ReadOptions& options = {});

// The channels of each canonical buffer readFrame would find in the file
// (options.only aside), from the header alone.
ChannelGroups bufferChannels(const std::string& path, const ReadOptions& options = {});

// Every channel name of a file (all parts), for listings and layer lookups.
std::vector<std::string> channelNames(const std::string& path);

// One frame from one file per buffer, as oidnDenoise takes them (EXR, PFM, HDR, ...):
// {"color": "beauty.pfm", "albedo": "alb.pfm", "normal": "nrm.pfm"}.
FrameBuffers readSeparateFiles(const std::map<std::string, std::string>& fileForBuffer);

// The first `channels` channels (or all when channels <= 0) of a plain image file,
// or the named channels if given.
Image readImage(const std::string& path, int channels = 3,
                const std::vector<std::string>& channelNames = {});

// Groups of named channels, one image each, in one decoding of the file (a
// multilayer EXR compresses every channel of a row block together, so each
// readImage decodes the whole file again). Placed by pixel coordinates in
// `window` (a frame's dataWindow); empty: the first channel's part's.
std::vector<Image> readImages(const std::string& path,
                              const std::vector<std::vector<std::string>>& groups,
                              const PixelWindow& window = {});

// Counts NaN/Inf values and replaces them by 0 (so metrics never silently average them).
std::size_t countAndZeroNonFinite(Image& image);

// True when every value of `image` is finite and half float holds it (|v| <= 65504).
bool fitsHalf(const Image& image);

struct WriteOptions {
  bool half = true;                          // half or float pixels for the result channels
  std::string layer = "Denoised";            // result layer name: "<layer>.R/G/B(/A)"
  bool rgbOnly = false;                      // plain RGB file, no other layers or metadata
  std::map<std::string, Image> extraLayers;  // more named layers, e.g. "uncertainty"
  // Where the result sits (the frame's data and display windows; empty: the
  // source part of the result's size) and the alpha it carries (empty: none).
  PixelWindow dataWindow;
  PixelWindow displayWindow;
  Image alpha;
};

// WriteOptions that place the result where `frame` was read from, as layer
// "Denoised" in its view layer, carrying its colour's alpha.
WriteOptions writeOptionsFor(const FrameBuffers& frame);

// Writes `result` as a named layer next to every layer and the metadata of
// `sourcePath` (or as plain RGB), keeping every part and its data window. A
// layer of that name already in the source (a Denoised layer from an earlier
// run, or Combined given as --layer) is replaced, not duplicated. A
// single-part source gets the layer in its part, a multi-part one (Blender 5)
// a new part named after the layer. Tiled and MIP-mapped sources are written
// as scanline files (level 0). Atomic: a temporary file is renamed into place.
// Refuses to write over `sourcePath` unless allowOverwriteSource is set.
void writeResult(const std::string& sourcePath, const std::string& outPath, const Image& result,
                 const WriteOptions& options, bool allowOverwriteSource = false);

// Writes a plain image (EXR/PFM/HDR/PNG/...) atomically. channelNames may be empty.
void writeImage(const std::string& path, const Image& image, bool half = false,
                const std::vector<std::string>& channelNames = {});

// The same with the stored pixel type chosen: 8 and 16-bit integer types take
// values in [0, 1] (clamped and rounded by OpenImageIO).
enum class PixelType { Half, Float, UInt8, UInt16 };
void writeImage(const std::string& path, const Image& image, PixelType type,
                const std::vector<std::string>& channelNames = {});

}  // namespace dn
