#include "dn/io/buffer_io.h"
#include "dn/io/output_files.h"

#include <OpenImageIO/half.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>

#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputPart.h>
#include <OpenEXR/ImfMultiPartInputFile.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <map>
#include <set>

#include <unistd.h>

namespace dn {

namespace OIIO = OIIO_NAMESPACE;
namespace fs = std::filesystem;

namespace {

constexpr int kStripRows = 64;  // rows per read/write strip: bounds memory on 4K frames

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw IoError(path + ": " + what);
}

std::string firstLine(std::string text) {
  auto nl = text.find('\n');
  if (nl != std::string::npos) text.resize(nl);
  return text.empty() ? "unknown error" : text;
}

std::string joined(const std::vector<std::string>& items) {
  std::string out;
  for (const auto& i : items) out += (out.empty() ? "" : ", ") + i;
  return out;
}

bool endsWith(const std::string& text, const std::string& tail) {
  return text.size() >= tail.size() &&
         text.compare(text.size() - tail.size(), tail.size(), tail) == 0;
}

PixelWindow dataWindowOf(const OIIO::ImageSpec& spec) {
  return {spec.x, spec.y, spec.width, spec.height};
}

PixelWindow displayWindowOf(const OIIO::ImageSpec& spec) {
  return {spec.full_x, spec.full_y, spec.full_width, spec.full_height};
}

// One part (OIIO subimage) of a file, level 0, with its channels' full names.
struct Part {
  OIIO::ImageSpec spec;
  std::vector<std::string> names;
};

// Where one channel lives in a file.
struct ChannelRef {
  int part;
  int index;
};

// All channels of all parts of an open file. Channels of a multi-part file
// that carry no layer (Nuke's "rgba" part with R, G, B, A) get the part's name
// as layer; Blender 5 already writes full names ("ViewLayer.Combined.R").
struct ChannelTable {
  std::vector<Part> parts;
  std::vector<std::string> ordered;          // every full name, in file order
  std::map<std::string, ChannelRef> byName;  // the first part wins a duplicate name

  bool has(const std::string& name) const { return byName.count(name) != 0; }
  const Part& partOf(const std::string& name) const { return parts[byName.at(name).part]; }
};

std::unique_ptr<OIIO::ImageInput> openInput(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) fail(path, "no such file");
  if (fs::is_directory(path, ec)) fail(path, "is a directory, not an image");
  auto in = OIIO::ImageInput::open(path);
  if (!in) fail(path, "cannot read as an image (" + firstLine(OIIO::geterror()) + ")");
  return in;
}

std::string fullChannelName(const OIIO::ImageSpec& spec, int c, bool multiPart) {
  const std::string& name = spec.channelnames[c];
  const std::string part = spec.get_string_attribute("oiio:subimagename");
  if (multiPart && !part.empty() && name.find('.') == std::string::npos) return part + "." + name;
  return name;
}

ChannelTable scanChannels(OIIO::ImageInput& in, const std::string& path) {
  ChannelTable table;
  for (int s = 0; in.seek_subimage(s, 0); ++s) {
    const OIIO::ImageSpec& spec = in.spec();
    if (spec.deep) fail(path, "is a deep image; flatten it first (oiiotool IN --flatten -o OUT)");
    table.parts.push_back(Part{spec, {}});
  }
  if (table.parts.empty()) fail(path, "has no readable image");
  const bool multiPart = table.parts.size() > 1;
  for (std::size_t p = 0; p < table.parts.size(); ++p) {
    Part& part = table.parts[p];
    for (int c = 0; c < part.spec.nchannels; ++c) {
      part.names.push_back(fullChannelName(part.spec, c, multiPart));
      if (table.byName.emplace(part.names.back(), ChannelRef{int(p), c}).second)
        table.ordered.push_back(part.names.back());
    }
  }
  return table;
}

// ---------------------------------------------------------------- lookup

// Channel suffixes of three-channel layers (Nuke spells them out) and of
// scalar layers (Mitsuba writes depth as "T").
const std::vector<std::vector<std::string>>& tripletSuffixes() {
  static const std::vector<std::vector<std::string>> sets = {
      {"R", "G", "B"}, {"X", "Y", "Z"}, {"r", "g", "b"}, {"x", "y", "z"}, {"red", "green", "blue"}};
  return sets;
}

bool isScalarSuffix(const std::string& s) {
  static const std::set<std::string> suffixes = {"Z", "V", "X", "R", "Y", "T", "z", "y"};
  return suffixes.count(s) != 0;
}

using Usable = std::function<bool(const std::string&)>;

// The channels of layer `base` ("" for none) as a buffer of `channels`
// channels, or an empty list.
std::vector<std::string> channelsOfLayer(const ChannelTable& table, const std::string& base,
                                         int channels, const Usable& usable) {
  auto present = [&](const std::string& n) { return table.has(n) && usable(n); };
  if (channels == 3) {
    for (const auto& suffixes : tripletSuffixes()) {
      std::vector<std::string> names;
      for (const auto& s : suffixes) names.push_back(base.empty() ? s : base + "." + s);
      if (std::all_of(names.begin(), names.end(), present)) return names;
    }
    // pbrt's older gbuffer names: Nx, Ny, Nz
    std::vector<std::string> joinedNames = {base + "x", base + "y", base + "z"};
    if (!base.empty() && std::all_of(joinedNames.begin(), joinedNames.end(), present))
      return joinedNames;
    return {};
  }
  if (base.empty()) return {};
  if (present(base)) return {base};  // a bare scalar channel such as "Z"
  // A layer of exactly one channel ("ViewLayer.Depth.Z", "depth.T"): a layer
  // of three ("transmission.R/G/B") is a colour, not this scalar.
  std::vector<std::string> inLayer;
  for (const auto& n : table.ordered)
    if (n.size() > base.size() + 1 && n.compare(0, base.size() + 1, base + ".") == 0 &&
        n.find('.', base.size() + 1) == std::string::npos)
      inLayer.push_back(n);
  if (inLayer.size() == 1 && isScalarSuffix(inLayer[0].substr(base.size() + 1)) &&
      usable(inLayer[0]))
    return inLayer;
  return {};
}

// Finds the channels of a canonical buffer under the view-layer prefixes, in
// order ("ViewLayer." then top level), or an empty list.
std::vector<std::string> resolveChannels(const ChannelTable& table, const BufferSpec& spec,
                                         const std::vector<std::string>& prefixes,
                                         const Usable& usable) {
  for (const auto& layer : spec.layers) {
    for (const auto& prefix : prefixes) {
      if (layer.empty() && !prefix.empty()) continue;  // plain R,G,B means no layer at all
      const std::string base = layer.empty() ? "" : prefix + layer;
      auto names = channelsOfLayer(table, base, spec.channels, usable);
      if (!names.empty()) return names;
    }
  }
  return {};
}

// The view layers: what stands in front of a colour pass, sorted
// ("ViewLayer.001" of "ViewLayer.001.Combined.R").
std::vector<std::string> findViewLayers(const ChannelTable& table) {
  std::vector<std::string> layers;
  for (const auto& name : table.ordered)
    for (const auto& pass : findBufferSpec("color")->layers) {
      if (pass.empty()) continue;
      for (const char* red : {"R", "r"}) {
        const std::string tail = "." + pass + "." + red;
        if (name.size() <= tail.size() || !endsWith(name, tail)) continue;
        std::string view = name.substr(0, name.size() - tail.size());
        if (std::find(layers.begin(), layers.end(), view) == layers.end()) layers.push_back(view);
      }
    }
  std::sort(layers.begin(), layers.end());  // OpenEXR stores a part's channels sorted anyway
  return layers;
}

// The view layer to read: the one asked for, else the only one. Blender's
// "Composite" (the compositor's output) is a view layer only when asked for.
std::string chooseViewLayer(const ChannelTable& table, const std::string& path,
                            const std::string& requested) {
  const std::vector<std::string> layers = findViewLayers(table);
  if (!requested.empty()) {
    if (std::find(layers.begin(), layers.end(), requested) == layers.end())
      fail(path, "has no view layer '" + requested +
                     "' (has: " + (layers.empty() ? std::string("none") : joined(layers)) + ")");
    return requested;
  }
  std::vector<std::string> candidates;
  for (const auto& l : layers)
    if (l != "Composite" || layers.size() == 1) candidates.push_back(l);
  if (candidates.size() > 1)
    fail(path, "has " + std::to_string(candidates.size()) + " view layers (" + joined(candidates) +
                   "); choose one with --view-layer NAME");
  return candidates.empty() ? "" : candidates.front();
}

// ---------------------------------------------------------------- pixels

// Rows read or written at once: bounds memory on 4K frames; whole tiles for
// tiled files, whose reads must start on a tile boundary.
int stripRows(const OIIO::ImageSpec& spec) {
  if (spec.tile_height <= 0) return kStripRows;
  return std::max(1, (kStripRows + spec.tile_height - 1) / spec.tile_height) * spec.tile_height;
}

// Rows [y0, y1) of channels [cb, ce) of one part, full width, as `type`.
bool readStrip(OIIO::ImageInput& in, int part, const OIIO::ImageSpec& spec, int y0, int y1, int cb,
               int ce, OIIO::TypeDesc type, void* out) {
  if (spec.tile_width > 0)
    return in.read_tiles(part, 0, spec.x, spec.x + spec.width, y0, y1, spec.z,
                         spec.z + std::max(1, spec.depth), cb, ce, type, out);
  return in.read_scanlines(part, 0, y0, y1, spec.z, cb, ce, type, out);
}

// `count` values of type T `strideBytes` apart, as float, to every `toStride`-th float of `to`.
template <class T>
void scatter(const unsigned char* from, int strideBytes, int count, float* to, int toStride) {
  for (int i = 0; i < count; ++i) {
    T value;
    std::memcpy(&value, from + std::size_t(i) * strideBytes, sizeof value);
    to[std::size_t(i) * toStride] = float(value);
  }
}

// How rows of channels [cb, ce) of one part are read: as stored where every
// channel is half or float (converted while scattered, so the channels between
// the wanted ones are never converted), else all as float.
struct StripLayout {
  OIIO::TypeDesc request = OIIO::TypeDesc::UNKNOWN;  // UNKNOWN: each channel as stored
  std::vector<int> offset;                           // bytes from a pixel's first channel
  std::vector<bool> half;
  int pixelBytes = 0;
};

StripLayout stripLayout(const OIIO::ImageSpec& spec, int cb, int ce) {
  StripLayout layout;
  for (int c = cb; c < ce; ++c) {
    const OIIO::TypeDesc type = spec.channelformat(c);
    if (type != OIIO::TypeDesc::HALF && type != OIIO::TypeDesc::FLOAT)
      layout.request = OIIO::TypeDesc::FLOAT;
  }
  for (int c = cb; c < ce; ++c) {
    const bool half =
        layout.request == OIIO::TypeDesc::UNKNOWN && spec.channelformat(c) == OIIO::TypeDesc::HALF;
    layout.offset.push_back(layout.pixelBytes);
    layout.half.push_back(half);
    layout.pixelBytes += half ? 2 : 4;
  }
  return layout;
}

// Where a channel read lands: its value of the window's first pixel, and
// the floats from one pixel to the next.
struct ChannelTarget {
  ChannelRef source;
  float* first;
  int stride;
};

// Rows of every target channel of part `p` through OpenImageIO, strip by
// strip: it returns every channel between the first and the last asked for.
void readPartThroughOiio(OIIO::ImageInput& in, const ChannelTable& table, const std::string& path,
                         int p, const std::vector<ChannelTarget>& targets,
                         const PixelWindow& window) {
  int lo = INT32_MAX, hi = -1;
  for (const auto& t : targets)
    if (t.source.part == p) lo = std::min(lo, t.source.index), hi = std::max(hi, t.source.index);
  const OIIO::ImageSpec& spec = table.parts[p].spec;
  const int x0 = std::max(spec.x, window.x),
            x1 = std::min(spec.x + spec.width, window.x + window.width);
  const int y0 = std::max(spec.y, window.y),
            y1 = std::min(spec.y + spec.height, window.y + window.height);
  if (x0 >= x1 || y0 >= y1) return;
  const StripLayout layout = stripLayout(spec, lo, hi + 1);
  const int rows = stripRows(spec);
  const std::size_t rowBytes = std::size_t(spec.width) * layout.pixelBytes;
  std::vector<unsigned char> strip(rowBytes * rows);
  for (int ys = spec.y + (y0 - spec.y) / rows * rows; ys < y1; ys += rows) {
    const int ye = std::min(spec.y + spec.height, ys + rows);
    if (!readStrip(in, p, spec, ys, ye, lo, hi + 1, layout.request, strip.data()))
      fail(path, "corrupt or truncated image data (" + firstLine(in.geterror()) + ")");
    // Row by row, so that the row stays in cache while every channel is taken from it.
    for (int y = std::max(ys, y0); y < std::min(ye, y1); ++y)
      for (const auto& t : targets) {
        if (t.source.part != p) continue;
        const int c = t.source.index - lo;
        const unsigned char* from = strip.data() + std::size_t(y - ys) * rowBytes +
                                    std::size_t(x0 - spec.x) * layout.pixelBytes + layout.offset[c];
        float* to =
            t.first + (std::size_t(y - window.y) * window.width + (x0 - window.x)) * t.stride;
        if (layout.half[c])
          scatter<Imath::half>(from, layout.pixelBytes, x1 - x0, to, t.stride);
        else
          scatter<float>(from, layout.pixelBytes, x1 - x0, to, t.stride);
      }
  }
}

// Whether OpenEXR itself can read part `p`'s target channels straight into
// their images: a scanline part whose columns lie within the window.
bool openExrReads(const OIIO::ImageInput& in, const ChannelTable& table, int p,
                  const PixelWindow& window) {
  const OIIO::ImageSpec& spec = table.parts[p].spec;
  return std::strcmp(in.format_name(), "openexr") == 0 && spec.tile_width == 0 &&
         spec.x >= window.x && spec.x + spec.width <= window.x + window.width;
}

// The target channels of the parts `parts` through OpenEXR itself, by name,
// straight into their images: the channels between those asked for are
// neither copied nor converted (a 1080p Blender frame with every pass has 43,
// of which a sequence reads about 30).
void readPartsThroughOpenExr(const std::string& path, const ChannelTable& table,
                             const std::set<int>& parts, const std::vector<ChannelTarget>& targets,
                             const PixelWindow& window) {
  try {
    Imf::MultiPartInputFile file(path.c_str());
    for (int p : parts) {
      Imf::InputPart part(file, p);
      const Imath::Box2i& data = part.header().dataWindow();
      const int y0 = std::max(data.min.y, window.y);
      const int y1 = std::min(data.max.y + 1, window.y + window.height);
      if (y0 >= y1) continue;
      // A channel asked for twice is read once (a frame buffer holds a name
      // once) and copied to the other place after.
      Imf::FrameBuffer buffer;
      std::map<std::string, const ChannelTarget*> readInto;
      std::vector<std::pair<const ChannelTarget*, const ChannelTarget*>> copies;
      for (const auto& t : targets) {
        if (t.source.part != p) continue;
        const std::string& name = table.parts[p].spec.channelnames[t.source.index];
        if (auto [first, fresh] = readInto.emplace(name, &t); !fresh) {
          copies.emplace_back(&t, first->second);
          continue;
        }
        buffer.insert(name, Imf::Slice::Make(Imf::FLOAT, t.first, Imath::V2i(window.x, window.y),
                                             window.width, window.height, sizeof(float) * t.stride,
                                             sizeof(float) * t.stride * window.width));
      }
      part.setFrameBuffer(buffer);
      part.readPixels(y0, y1 - 1);
      const std::size_t from = std::size_t(y0 - window.y) * window.width;
      const std::size_t to = std::size_t(y1 - window.y) * window.width;
      for (const auto& [copy, read] : copies)
        for (std::size_t i = from; i < to; ++i)
          copy->first[i * copy->stride] = read->first[i * read->stride];
    }
  } catch (const std::exception& e) {
    fail(path, "corrupt or truncated image data (" + firstLine(e.what()) + ")");
  }
}

// Reads groups of named channels into one interleaved float image per group,
// covering `window`, by pixel coordinates: where a channel's part has no data, 0.
// Each part's rows are decompressed once for every group.
std::vector<Image> readChannelGroups(OIIO::ImageInput& in, const ChannelTable& table,
                                     const std::string& path,
                                     const std::vector<std::vector<std::string>>& groups,
                                     const PixelWindow& window) {
  std::vector<Image> images;
  std::vector<ChannelTarget> targets;
  images.reserve(groups.size());
  for (const auto& names : groups) {
    images.emplace_back(window.width, window.height, static_cast<int>(names.size()));
    for (std::size_t c = 0; c < names.size(); ++c) {
      auto it = table.byName.find(names[c]);
      if (it == table.byName.end()) fail(path, "has no channel '" + names[c] + "'");
      targets.push_back({it->second, images.back().pixels.data() + c, images.back().channels});
    }
  }
  std::set<int> parts, byOpenExr;
  for (const auto& t : targets) parts.insert(t.source.part);
  for (int p : parts)
    if (openExrReads(in, table, p, window))
      byOpenExr.insert(p);
    else
      readPartThroughOiio(in, table, path, p, targets, window);
  if (!byOpenExr.empty()) readPartsThroughOpenExr(path, table, byOpenExr, targets, window);
  return images;
}

Image readChannels(OIIO::ImageInput& in, const ChannelTable& table, const std::string& path,
                   const std::vector<std::string>& names, const PixelWindow& window) {
  return std::move(readChannelGroups(in, table, path, {names}, window).front());
}

// Temporary name in the destination's folder with the same extension, so the
// image writer picks the right format and rename() stays on one file system.
std::string temporaryPathFor(const std::string& path) {
  static std::atomic<int> counter{0};
  fs::path p(path);
  std::string name = "." + p.stem().string() + ".tmp" + std::to_string(::getpid()) + "-" +
                     std::to_string(counter++) + p.extension().string();
  return (p.parent_path() / name).string();
}

// Runs `write(tmp)` then renames into place; no partial file survives a failure.
template <class WriteFn>
void writeAtomically(const std::string& path, WriteFn&& write) {
  std::error_code ec;
  fs::path parent = fs::path(path).parent_path();
  if (!parent.empty() && !fs::is_directory(parent, ec)) fail(path, "output folder does not exist");
  const std::string tmp = temporaryPathFor(path);
  trackTemporaryFile(tmp);  // a SIGTERM handler removes it (dn/io/output_files.h)
  try {
    write(tmp);
    fs::rename(tmp, path);
  } catch (const fs::filesystem_error& e) {
    fs::remove(tmp, ec);
    untrackTemporaryFile(tmp);
    fail(path, std::string("cannot write (") + e.code().message() + ")");
  } catch (...) {
    fs::remove(tmp, ec);
    untrackTemporaryFile(tmp);
    throw;
  }
  untrackTemporaryFile(tmp);
}

// The process's provenance (dn/io/output_files.h); ImageHistory grows by a line.
void addProvenance(OIIO::ImageSpec& spec) {
  for (const auto& [name, value] : provenance()) {
    std::string text = value;
    if (name == "ImageHistory") {
      const std::string before = spec.get_string_attribute("ImageHistory");
      if (!before.empty()) text = before + "\n" + value;
    }
    spec.attribute(name, text);
  }
}

bool hasExtension(const std::string& path, const std::string& ext) {
  std::string e = fs::path(path).extension().string();
  std::transform(e.begin(), e.end(), e.begin(), ::tolower);
  return e == ext;
}

// Debian's OpenImageIO 2.4 reads PFM but cannot write it: a little-endian
// colour ("PF") or greyscale ("Pf") float map, rows stored bottom to top.
void writePfm(const std::string& tmp, const std::string& path, const Image& image) {
  if (image.channels != 1 && image.channels != 3)
    fail(path, "PFM holds 1 or 3 channels, not " + std::to_string(image.channels));
  std::FILE* file = std::fopen(tmp.c_str(), "wb");
  if (!file) fail(path, "cannot open for writing");
  std::fprintf(file, "%s\n%d %d\n-1.0\n", image.channels == 3 ? "PF" : "Pf", image.width,
               image.height);
  const std::size_t rowFloats = static_cast<std::size_t>(image.width) * image.channels;
  bool ok = true;
  for (int y = image.height - 1; y >= 0 && ok; --y)
    ok = std::fwrite(image.pixel(0, y), sizeof(float), rowFloats, file) == rowFloats;
  ok = std::fclose(file) == 0 && ok;
  if (!ok) fail(path, "write failed (disk full?)");
}

std::unique_ptr<OIIO::ImageOutput> createOutput(const std::string& tmp, const std::string& path) {
  auto out = OIIO::ImageOutput::create(tmp);
  if (!out) fail(path, "unsupported output format (" + firstLine(OIIO::geterror()) + ")");
  return out;
}

}  // namespace

std::pair<std::string, std::vector<std::string>> parseChannelOverride(const std::string& text) {
  auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == text.size())
    throw std::invalid_argument("bad channel mapping '" + text +
                                "' (expected BUFFER=CHAN,CHAN,CHAN)");
  std::string buffer = text.substr(0, eq);
  if (!findBufferSpec(buffer))
    throw std::invalid_argument("unknown buffer '" + buffer + "' in '" + text + "'");
  std::vector<std::string> channels;
  std::size_t start = eq + 1;
  while (start <= text.size()) {
    auto comma = text.find(',', start);
    if (comma == std::string::npos) comma = text.size();
    channels.push_back(text.substr(start, comma - start));
    start = comma + 1;
  }
  if (static_cast<int>(channels.size()) != findBufferSpec(buffer)->channels)
    throw std::invalid_argument("buffer '" + buffer + "' needs " +
                                std::to_string(findBufferSpec(buffer)->channels) +
                                " channels in '" + text + "'");
  return {buffer, channels};
}

namespace {

// A canonical buffer found in a file: its channels, all in one display window.
struct Located {
  std::string buffer;
  std::vector<std::string> channels;
};

// Every canonical buffer the file holds (in canonical order) with its channels:
// the overrides, else the names found in the chosen view layer. Buffers from a
// part with another display window than the colour's (a preview) are not used.
std::vector<Located> locateBuffers(const ChannelTable& table, const std::string& path,
                                   const ReadOptions& options) {
  const std::string view = chooseViewLayer(table, path, options.viewLayer);
  std::vector<std::string> prefixes;
  if (!view.empty()) prefixes.push_back(view + ".");
  prefixes.push_back("");

  auto channelsFor = [&](const BufferSpec& spec, const Usable& usable) {
    auto override = options.overrides.find(spec.name);
    if (override != options.overrides.end()) return override->second;
    return resolveChannels(table, spec, prefixes, usable);
  };
  std::vector<Located> located;
  const auto color = channelsFor(*findBufferSpec("color"), [](const std::string&) { return true; });
  if (!color.empty() && table.has(color.front())) {
    const PixelWindow frame = displayWindowOf(table.partOf(color.front()).spec);
    const Usable sameFrame = [&table, frame](const std::string& n) {
      return displayWindowOf(table.partOf(n).spec) == frame;
    };
    for (const auto& spec : canonicalBuffers()) {
      auto names = spec.name == "color" ? color : channelsFor(spec, sameFrame);
      if (!names.empty()) located.push_back({spec.name, std::move(names)});
    }
    return located;
  }
  if (!color.empty()) located.push_back({"color", color});  // an override naming no channel
  for (const auto& spec : canonicalBuffers())
    if (spec.name != "color") {
      auto names = channelsFor(spec, [](const std::string&) { return true; });
      if (!names.empty()) located.push_back({spec.name, std::move(names)});
    }
  return located;
}

// The alpha beside the colour's channels: "ViewLayer.Combined.A" for
// "ViewLayer.Combined.R", "A" for "R"; "" when there is none.
std::string alphaChannelOf(const ChannelTable& table, const std::vector<std::string>& color) {
  if (color.empty() || !table.has(color.front())) return "";
  const std::string& red = color.front();
  const auto dot = red.rfind('.');
  const std::string layer = dot == std::string::npos ? "" : red.substr(0, dot + 1);
  const int part = table.byName.at(red).part;
  // RenderMan may write Ci.r, Ci.g, Ci.b with a bare alpha "a".
  const std::vector<std::string> layers = layer.find('.') == layer.size() - 1
                                              ? std::vector<std::string>{layer, ""}
                                              : std::vector<std::string>{layer};
  for (const auto& l : layers)
    for (const char* a : {"A", "a"})
      if (table.has(l + a) && table.byName.at(l + a).part == part) return l + a;
  return "";
}

float srgbToLinear(float v) {
  return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f);
}

// 8- and 16-bit images (PNG, JPEG, TIFF) store colours sRGB-encoded; the model
// works on linear radiance and albedo.
bool storedAsSrgb(const OIIO::ImageSpec& spec) {
  const bool integer = spec.format.basetype != OIIO::TypeDesc::FLOAT &&
                       spec.format.basetype != OIIO::TypeDesc::HALF &&
                       spec.format.basetype != OIIO::TypeDesc::DOUBLE;
  const std::string space = spec.get_string_attribute("oiio:ColorSpace");
  return integer && (space.empty() || OIIO::Strutil::iequals(space, "sRGB"));
}

void linearizeIfSrgb(Image& image, const OIIO::ImageSpec& spec, const std::string& buffer,
                     std::vector<std::string>& notes) {
  if (!storedAsSrgb(spec)) return;
  for (float& v : image.pixels) v = srgbToLinear(v);
  notes.push_back(buffer + ": " + spec.format.c_str() +
                  " pixels read as sRGB-encoded and converted to linear");
}

// Normals stored as (n + 1) / 2 (image formats without negative values, some
// renderers' defaults) are decoded; the model was trained on Cycles' world-space
// normals in [-1, 1]. Every decision is one line in `notes`.
void decodeNormals(Image& normal, const std::vector<std::string>& source,
                   std::vector<std::string>& notes) {
  std::size_t lit = 0, rawUnit = 0, encodedUnit = 0;
  bool nonNegative = true;
  for (std::size_t i = 0; i < normal.pixelCount(); ++i) {
    const float* n = &normal.pixels[i * 3];
    if (n[0] == 0.0f && n[1] == 0.0f && n[2] == 0.0f) continue;  // background
    ++lit;
    nonNegative = nonNegative && n[0] >= 0.0f && n[1] >= 0.0f && n[2] >= 0.0f;
    const double raw = std::sqrt(double(n[0]) * n[0] + double(n[1]) * n[1] + double(n[2]) * n[2]);
    double encoded = 0.0;
    for (int c = 0; c < 3; ++c) encoded += (2.0 * n[c] - 1.0) * (2.0 * n[c] - 1.0);
    rawUnit += std::abs(raw - 1.0) < 0.1;
    encodedUnit += std::abs(std::sqrt(encoded) - 1.0) < 0.1;
  }
  if (lit == 0) return;
  const std::string from = "normal (" + joined(source) + ")";
  auto percent = [lit](std::size_t n) { return std::to_string(100 * n / lit) + " %"; };
  if (nonNegative && encodedUnit * 2 >= lit && encodedUnit > rawUnit) {
    for (std::size_t i = 0; i < normal.pixelCount(); ++i) {
      float* n = &normal.pixels[i * 3];
      if (n[0] == 0.0f && n[1] == 0.0f && n[2] == 0.0f) continue;
      for (int c = 0; c < 3; ++c) n[c] = 2.0f * n[c] - 1.0f;
    }
    notes.push_back(
        from + ": stored as (n + 1) / 2 (no negative component, |2n - 1| within 10 % of 1 in " +
        percent(encodedUnit) + " of pixels); decoded to [-1, 1]");
  } else if (rawUnit * 2 < lit) {
    notes.push_back(from + ": lengths are not near 1 (within 10 % in " + percent(rawUnit) +
                    " of pixels); used as stored");
  }
  const std::string& first = source.front();
  if (first.find("Denoising Normal") == std::string::npos &&
      first.find("Normal.") == std::string::npos)
    notes.push_back(from + ": taken as world-space, as Cycles writes normals");
}

// Reads the located buffers of an open file into a frame: the colour's data
// window, its alpha, and the notes on what was decoded.
FrameBuffers readLocated(OIIO::ImageInput& in, const ChannelTable& table, const std::string& path,
                         const std::vector<Located>& located, const ReadOptions& options) {
  FrameBuffers frame;
  const std::vector<std::string>* color = nullptr;
  for (const auto& l : located)
    if (l.buffer == "color") color = &l.channels;
  if (!color) return frame;
  for (const auto& name : *color)
    if (!table.has(name)) fail(path, "has no channel '" + name + "'");
  const OIIO::ImageSpec& colorSpec = table.partOf(color->front()).spec;
  frame.dataWindow = dataWindowOf(colorSpec);
  frame.displayWindow = displayWindowOf(colorSpec);
  frame.width = frame.dataWindow.width;
  frame.height = frame.dataWindow.height;
  // One read for every wanted buffer and the alpha: a channel's rows are
  // decompressed with every other channel of its part, so a read per buffer
  // decompressed a 57-layer 1080p frame 15 times (half of `-q fast`'s CPU time).
  std::vector<const Located*> wanted;
  std::vector<std::vector<std::string>> groups;
  for (const auto& l : located)
    if (options.only.empty() ||
        std::find(options.only.begin(), options.only.end(), l.buffer) != options.only.end()) {
      wanted.push_back(&l);
      groups.push_back(l.channels);
    }
  for (const auto& [name, channels] : options.extra) {
    if (channels.empty()) fail(path, "an empty channel group was asked for");
    groups.push_back(channels);
  }
  const std::string alpha = alphaChannelOf(table, *color);
  if (!alpha.empty()) groups.push_back({alpha});
  std::vector<Image> images = readChannelGroups(in, table, path, groups, frame.dataWindow);
  for (std::size_t i = 0; i < wanted.size(); ++i) {
    const std::string& name = wanted[i]->buffer;
    const std::vector<std::string>& channels = wanted[i]->channels;
    Image& image = images[i];
    const OIIO::ImageSpec& spec = table.partOf(channels.front()).spec;
    if (name == "color" || name == "albedo") linearizeIfSrgb(image, spec, name, frame.notes);
    if (name == "normal") decodeNormals(image, channels, frame.notes);
    frame.buffers[name] = std::move(image);
    frame.sourceChannels[name] = channels;
  }
  std::size_t next = wanted.size();
  for (const auto& entry : options.extra) frame.extra[entry.first] = std::move(images[next++]);
  if (!alpha.empty()) frame.alpha = std::move(images.back());
  if (color->front().find("Noisy Image") != std::string::npos)
    frame.notes.push_back("color: from '" + color->front().substr(0, color->front().rfind('.')) +
                          "' (Cycles' own denoiser ran, so Combined is already denoised)");
  return frame;
}

namespace {

// The sample count Cycles writes as "cycles.<view layer>.samples": the colour's
// view layer first, else the only such attribute. 0 when absent or unreadable.
int recordedSamples(const OIIO::ImageSpec& spec, const std::string& layerPrefix) {
  auto parse = [](const OIIO::ParamValue& p) {
    const std::string text = p.get_string();
    char* end = nullptr;
    const long n = std::strtol(text.c_str(), &end, 10);
    return end != text.c_str() && *end == '\0' && n > 0 && n < (1L << 30) ? int(n) : 0;
  };
  const std::string prefix = "cycles.", suffix = ".samples";
  std::vector<const OIIO::ParamValue*> found;
  for (const auto& p : spec.extra_attribs) {
    const std::string name = p.name().string();
    if (name.size() <= prefix.size() + suffix.size() || name.rfind(prefix, 0) != 0 ||
        name.compare(name.size() - suffix.size(), suffix.size(), suffix) != 0)
      continue;
    if (!layerPrefix.empty() && name == prefix + layerPrefix + "samples") return parse(p);
    found.push_back(&p);
  }
  return found.size() == 1 ? parse(*found.front()) : 0;
}

}  // namespace

}  // namespace

std::vector<std::string> viewLayers(const std::string& path) {
  auto in = openInput(path);
  return findViewLayers(scanChannels(*in, path));
}

std::vector<std::string> availableBuffers(const std::string& path, const ReadOptions& options) {
  auto in = openInput(path);
  std::vector<std::string> names;
  for (const auto& l : locateBuffers(scanChannels(*in, path), path, options))
    names.push_back(l.buffer);
  return names;
}

ChannelGroups bufferChannels(const std::string& path, const ReadOptions& options) {
  auto in = openInput(path);
  ChannelGroups channels;
  for (const auto& l : locateBuffers(scanChannels(*in, path), path, options))
    channels[l.buffer] = l.channels;
  return channels;
}

FrameBuffers readFrame(const std::string& path, const ReadOptions& options) {
  auto in = openInput(path);
  ChannelTable table = scanChannels(*in, path);
  const std::vector<Located> located = locateBuffers(table, path, options);
  FrameBuffers frame = readLocated(*in, table, path, located, options);
  if (!frame.has("color")) {
    std::vector<std::string> all = table.ordered;
    if (all.size() > 12) all.resize(12), all.push_back("...");
    fail(path, "no colour channels found (looked for Combined.RGB, R,G,B, rgba, beauty; file has " +
                   joined(all) + "); map them with --channels color=R,G,B");
  }
  for (const auto& name : options.only)
    if (!frame.has(name)) fail(path, "has no '" + name + "' buffer");
  frame.samplesPerPixel = recordedSamples(
      table.partOf(frame.sourceChannels.at("color").front()).spec, layerPrefixOf(frame));
  for (const auto& l : located)
    if (!frame.has(l.buffer)) frame.unread.push_back(l.buffer);
  if (!frame.unread.empty())
    frame.readUnread = [path, options](const std::vector<std::string>& names) {
      ReadOptions more = options;
      more.only = names;
      more.extra.clear();
      auto again = openInput(path);
      const ChannelTable table = scanChannels(*again, path);
      return readLocated(*again, table, path, locateBuffers(table, path, more), more).buffers;
    };
  return frame;
}

std::vector<std::string> channelNames(const std::string& path) {
  auto in = openInput(path);
  return scanChannels(*in, path).ordered;
}

namespace {

// The channels readImage reads when none are named: the colour of a
// multilayer file for 3, else the first `channels` of the first part.
std::vector<std::string> defaultImageChannels(const ChannelTable& table, const std::string& path,
                                              int channels) {
  const Part& first = table.parts.front();
  const int n = channels <= 0 ? first.spec.nchannels : channels;
  if (first.spec.nchannels < n && !(n == 3 && table.ordered.size() > 3))
    fail(path,
         "has " + std::to_string(first.spec.nchannels) + " channels, needs " + std::to_string(n));
  if (n == 3 && table.ordered.size() > 3) {  // prefer the colour of a multilayer file
    for (const auto& l : locateBuffers(table, path, ReadOptions{}))
      if (l.buffer == "color") return l.channels;
    if (first.spec.nchannels < 3) fail(path, "no colour channels found");
  }
  return std::vector<std::string>(first.names.begin(), first.names.begin() + n);
}

}  // namespace

Image readImage(const std::string& path, int channels, const std::vector<std::string>& names) {
  auto in = openInput(path);
  ChannelTable table = scanChannels(*in, path);
  const std::vector<std::string> wanted =
      names.empty() ? defaultImageChannels(table, path, channels) : names;
  for (const auto& n : wanted)
    if (!table.has(n)) fail(path, "has no channel '" + n + "'");
  return readChannels(*in, table, path, wanted, dataWindowOf(table.partOf(wanted.front()).spec));
}

std::vector<Image> readImages(const std::string& path,
                              const std::vector<std::vector<std::string>>& groups,
                              const PixelWindow& window) {
  if (groups.empty()) return {};
  auto in = openInput(path);
  ChannelTable table = scanChannels(*in, path);
  for (const auto& group : groups) {
    if (group.empty()) fail(path, "an empty channel group was asked for");
    for (const auto& n : group)
      if (!table.has(n)) fail(path, "has no channel '" + n + "'");
  }
  return readChannelGroups(
      *in, table, path, groups,
      window.empty() ? dataWindowOf(table.partOf(groups.front().front()).spec) : window);
}

namespace {

std::string sizeText(const PixelWindow& w) {
  return std::to_string(w.width) + "x" + std::to_string(w.height);
}

// One buffer from its own file (EXR, PFM, HDR, PNG, ...), placed in the
// colour's data window by pixel coordinates.
Image readBufferFile(const std::string& path, const BufferSpec& spec, FrameBuffers& frame) {
  auto in = openInput(path);
  ChannelTable table = scanChannels(*in, path);
  std::vector<std::string> channels;  // the buffer's own names first: albedo.R of an AOV file
  for (const auto& l : locateBuffers(table, path, ReadOptions{}))
    if (l.buffer == spec.name && spec.name != "color") channels = l.channels;
  if (channels.empty()) channels = defaultImageChannels(table, path, spec.channels);
  const OIIO::ImageSpec& source = table.partOf(channels.front()).spec;
  if (frame.buffers.empty()) {  // the colour: it sets the frame
    frame.dataWindow = dataWindowOf(source);
    frame.displayWindow = displayWindowOf(source);
    frame.width = frame.dataWindow.width;
    frame.height = frame.dataWindow.height;
    const std::string alpha = alphaChannelOf(table, channels);
    if (!alpha.empty()) frame.alpha = readChannels(*in, table, path, {alpha}, frame.dataWindow);
  } else if (displayWindowOf(source) != frame.displayWindow) {
    fail(path, "is " + sizeText(displayWindowOf(source)) + " but the colour image is " +
                   sizeText(frame.displayWindow));
  }
  Image image = readChannels(*in, table, path, channels, frame.dataWindow);
  if (spec.name == "color" || spec.name == "albedo")
    linearizeIfSrgb(image, source, spec.name, frame.notes);
  if (spec.name == "normal") decodeNormals(image, channels, frame.notes);
  frame.sourceChannels[spec.name] = channels;
  return image;
}

}  // namespace

FrameBuffers readSeparateFiles(const std::map<std::string, std::string>& fileForBuffer) {
  auto color = fileForBuffer.find("color");
  if (color == fileForBuffer.end()) throw IoError("(arguments): a colour image is required");
  FrameBuffers frame;
  frame.buffers["color"] = readBufferFile(color->second, *findBufferSpec("color"), frame);
  for (const auto& [buffer, path] : fileForBuffer) {
    if (buffer == "color") continue;
    const BufferSpec* spec = findBufferSpec(buffer);
    if (!spec) fail(path, "unknown buffer name '" + buffer + "'");
    frame.buffers[buffer] = readBufferFile(path, *spec, frame);
  }
  frame.sourceChannels.erase("color");  // the layer prefix of a separate file means nothing
  return frame;
}

std::size_t countAndZeroNonFinite(Image& image) {
  std::size_t count = 0;
  for (float& v : image.pixels)
    if (!std::isfinite(v)) v = 0.0f, ++count;
  return count;
}

bool fitsHalf(const Image& image) {
  constexpr float kHalfMax = 65504.0f;
  return std::all_of(image.pixels.begin(), image.pixels.end(),
                     [](float v) { return std::isfinite(v) && std::abs(v) <= kHalfMax; });
}

namespace {

// Writes one plain image; windows that are set place it in a larger frame.
void writePlain(const std::string& path, const Image& image, PixelType type,
                const std::vector<std::string>& channelNames, const PixelWindow& data,
                const PixelWindow& display) {
  static const std::map<PixelType, OIIO::TypeDesc> kTypes = {
      {PixelType::Half, OIIO::TypeDesc::HALF},
      {PixelType::Float, OIIO::TypeDesc::FLOAT},
      {PixelType::UInt8, OIIO::TypeDesc::UINT8},
      {PixelType::UInt16, OIIO::TypeDesc::UINT16}};
  if (image.empty()) fail(path, "refusing to write an empty image");
  writeAtomically(path, [&](const std::string& tmp) {
    if (hasExtension(path, ".pfm")) return writePfm(tmp, path, image);
    auto out = createOutput(tmp, path);
    OIIO::ImageSpec spec(image.width, image.height, image.channels, kTypes.at(type));
    if (!channelNames.empty()) spec.channelnames = channelNames;
    if (!data.empty() && data.width == image.width && data.height == image.height &&
        out->supports("displaywindow")) {
      spec.x = data.x, spec.y = data.y;
      if (!display.empty())
        spec.full_x = display.x, spec.full_y = display.y, spec.full_width = display.width,
        spec.full_height = display.height;
    }
    addProvenance(spec);
    if (!out->open(tmp, spec) || !out->write_image(OIIO::TypeDesc::FLOAT, image.pixels.data()) ||
        !out->close())
      fail(path, "write failed (" + firstLine(out->geterror()) + ")");
  });
}

// The layer of a full channel name: "ViewLayer.Denoised" of "ViewLayer.Denoised.R".
std::string layerOf(const std::string& channel) {
  const auto dot = channel.rfind('.');
  return dot == std::string::npos ? "" : channel.substr(0, dot);
}

// One layer to add to the output: its name and interleaved channels.
struct AddedLayer {
  std::string name;
  std::vector<std::string> suffixes;
  std::vector<const Image*> sources;  // one image per group of channels
};

std::vector<AddedLayer> addedLayers(const Image& result, const WriteOptions& options,
                                    const PixelWindow& window, const std::string& outPath,
                                    const std::string& sourcePath) {
  std::vector<AddedLayer> added;
  auto sizeCheck = [&](const std::string& layer, const Image& image) {
    if (image.width != window.width || image.height != window.height)
      fail(outPath, "layer '" + layer + "' size does not match " + sourcePath);
  };
  sizeCheck(options.layer, result);
  AddedLayer main{options.layer, {}, {&result}};
  static const char* rgb[] = {"R", "G", "B", "A"};
  for (int c = 0; c < result.channels; ++c)
    main.suffixes.push_back(result.channels <= 4 ? rgb[c] : std::to_string(c));
  if (!options.alpha.empty() && result.channels == 3) {
    sizeCheck(options.layer, options.alpha);
    main.suffixes.push_back("A");
    main.sources.push_back(&options.alpha);
  }
  added.push_back(main);
  for (const auto& [name, image] : options.extraLayers) {
    sizeCheck(name, image);
    AddedLayer extra{name, {}, {&image}};
    for (int c = 0; c < image.channels; ++c)
      extra.suffixes.push_back(image.channels == 1   ? std::string("Y")
                               : image.channels <= 4 ? std::string(rgb[c])
                                                     : std::to_string(c));
    added.push_back(extra);
  }
  return added;
}

// Value of channel k of an added layer at (x, y) in its window.
float addedValue(const AddedLayer& layer, int k, int x, int y) {
  for (const Image* image : layer.sources) {
    if (k < image->channels) return image->at(x, y, k);
    k -= image->channels;
  }
  return 0.0f;
}

// What one output part holds: which source part channels it copies (in
// order) and which added layers follow them.
struct OutputPart {
  OIIO::ImageSpec spec;
  int sourcePart = -1;           // -1: a new part holding added layers only
  std::vector<int> kept;         // channel indices of the source part
  std::vector<int> addedLayers;  // indices into the added layers
};

// A spec written as scanlines at MIP level 0 only, with the given channels.
void makePlainScanline(OIIO::ImageSpec& spec) {
  spec.tile_width = spec.tile_height = 0;
  spec.tile_depth = 1;
  spec.erase_attribute("openexr:levelmode");
  spec.erase_attribute("openexr:roundingmode");
  spec.alpha_channel = -1;
  spec.z_channel = -1;
}

// The source part the result belongs in: the one with the result's data window.
int anchorPart(const ChannelTable& table, const WriteOptions& options, const Image& result) {
  for (std::size_t p = 0; p < table.parts.size(); ++p) {
    const PixelWindow data = dataWindowOf(table.parts[p].spec);
    if (!options.dataWindow.empty() ? data == options.dataWindow
                                    : data.width == result.width && data.height == result.height)
      return int(p);
  }
  return -1;
}

std::vector<OutputPart> planOutputParts(const ChannelTable& table,
                                        const std::vector<AddedLayer>& added, int anchor,
                                        OIIO::TypeDesc resultType) {
  std::set<std::string> replaced;
  for (const auto& layer : added) replaced.insert(layer.name);
  std::vector<OutputPart> parts;
  for (std::size_t p = 0; p < table.parts.size(); ++p) {
    const Part& source = table.parts[p];
    OutputPart out{source.spec, int(p), {}, {}};
    if (out.spec.channelformats.empty())
      out.spec.channelformats.assign(out.spec.nchannels, out.spec.format);
    std::vector<std::string> names;
    std::vector<OIIO::TypeDesc> formats;
    for (int c = 0; c < source.spec.nchannels; ++c) {
      if (replaced.count(layerOf(source.names[c]))) continue;  // an earlier result: replaced
      out.kept.push_back(c);
      names.push_back(source.spec.channelnames[c]);
      formats.push_back(out.spec.channelformats[c]);
    }
    if (out.kept.empty()) continue;
    out.spec.channelnames = names;
    out.spec.channelformats = formats;
    out.spec.nchannels = int(names.size());
    makePlainScanline(out.spec);
    parts.push_back(std::move(out));
  }
  const bool singlePart = table.parts.size() == 1 && !parts.empty();
  for (std::size_t a = 0; a < added.size(); ++a) {
    // Single-part files get every layer in their part; multi-part ones (Blender
    // 5) one new part per layer, named after it, as Blender writes passes.
    OutputPart* target = singlePart ? &parts.front() : nullptr;
    if (!target) {
      OutputPart fresh{table.parts[anchor].spec, -1, {}, {}};
      fresh.spec.channelnames.clear();
      fresh.spec.channelformats.clear();
      fresh.spec.nchannels = 0;
      fresh.spec.attribute("oiio:subimagename", added[a].name);
      fresh.spec.attribute("name", added[a].name);
      makePlainScanline(fresh.spec);
      parts.push_back(std::move(fresh));
      target = &parts.back();
    }
    for (const auto& suffix : added[a].suffixes) {
      target->spec.channelnames.push_back(added[a].name + "." + suffix);
      target->spec.channelformats.push_back(resultType);
    }
    target->spec.nchannels = int(target->spec.channelnames.size());
    target->addedLayers.push_back(int(a));
  }
  return parts;
}

bool halfOrFloat(OIIO::TypeDesc type) {
  return type == OIIO::TypeDesc::HALF || type == OIIO::TypeDesc::FLOAT;
}

// Byte offsets of each channel in a pixel laid out as `spec` says; the last
// entry is the pixel's size.
std::vector<int> byteOffsets(const OIIO::ImageSpec& spec) {
  std::vector<int> offsets = {0};
  for (int c = 0; c < spec.nchannels; ++c)
    offsets.push_back(offsets.back() + static_cast<int>(spec.channelformat(c).size()));
  return offsets;
}

// A run of bytes copied unchanged from a source pixel to an output pixel.
struct ByteRun {
  int from, to, bytes;
};

// The kept channels as runs of consecutive bytes (usually one run), given the
// source pixel's byte offsets.
std::vector<ByteRun> keptRuns(const OutputPart& part, const std::vector<int>& in) {
  std::vector<ByteRun> runs;
  int to = 0;
  for (int k : part.kept) {
    const int size = in[k + 1] - in[k];
    if (!runs.empty() && runs.back().from + runs.back().bytes == in[k])
      runs.back().bytes += size;
    else
      runs.push_back({in[k], to, size});
    to += size;
  }
  return runs;
}

// Copies one output part strip by strip: the kept source channels as stored
// (half stays half: no conversion, which was most of the write's time), then
// the added layers inside the result's window. A source with channels other
// than half or float goes through float.
void writePart(OIIO::ImageInput& in, OIIO::ImageOutput& out, const OutputPart& part,
               const ChannelTable& table, const std::vector<AddedLayer>& added,
               const PixelWindow& window, const std::string& sourcePath,
               const std::string& outPath) {
  const OIIO::ImageSpec& spec = part.spec;
  const OIIO::ImageSpec* source =
      part.sourcePart >= 0 ? &table.parts[part.sourcePart].spec : nullptr;
  bool native = true;
  for (int c = 0; c < spec.nchannels; ++c) native = native && halfOrFloat(spec.channelformat(c));
  for (int c = 0; source && c < source->nchannels; ++c)
    native = native && halfOrFloat(source->channelformat(c));
  const OIIO::TypeDesc request = native ? OIIO::TypeDesc::UNKNOWN : OIIO::TypeDesc::FLOAT;
  auto layoutOf = [native](OIIO::ImageSpec s) {  // the strips' layout
    if (!native) s.channelformats.assign(s.nchannels, OIIO::TypeDesc::FLOAT);
    return s;
  };
  const std::vector<int> inOffsets = source ? byteOffsets(layoutOf(*source)) : std::vector<int>{0};
  const std::vector<int> outOffsets = byteOffsets(layoutOf(spec));
  const int inPixel = inOffsets.back(), outPixel = outOffsets.back();
  const std::vector<ByteRun> runs = source ? keptRuns(part, inOffsets) : std::vector<ByteRun>();
  const int rows = source ? stripRows(*source) : kStripRows;
  std::vector<unsigned char> inStrip(static_cast<std::size_t>(spec.width) * rows *
                                     std::max(1, inPixel));
  std::vector<unsigned char> outStrip(static_cast<std::size_t>(spec.width) * rows * outPixel);
  const int firstAdded = static_cast<int>(part.kept.size());
  for (int y0 = spec.y; y0 < spec.y + spec.height; y0 += rows) {
    const int y1 = std::min(spec.y + spec.height, y0 + rows);
    if (source && !readStrip(in, part.sourcePart, *source, y0, y1, 0, source->nchannels, request,
                             inStrip.data()))
      fail(sourcePath, "corrupt or truncated image data (" + firstLine(in.geterror()) + ")");
    for (int y = y0; y < y1; ++y)
      for (int x = spec.x; x < spec.x + spec.width; ++x) {
        const std::size_t pixel = static_cast<std::size_t>(y - y0) * spec.width + (x - spec.x);
        const unsigned char* from = &inStrip[pixel * inPixel];
        unsigned char* to = &outStrip[pixel * outPixel];
        for (const ByteRun& run : runs) std::memcpy(to + run.to, from + run.from, run.bytes);
        const int rx = x - window.x, ry = y - window.y;
        const bool inside = rx >= 0 && ry >= 0 && rx < window.width && ry < window.height;
        int c = firstAdded;
        for (int a : part.addedLayers)
          for (std::size_t k = 0; k < added[a].suffixes.size(); ++k, ++c) {
            const float value = inside ? addedValue(added[a], int(k), rx, ry) : 0.0f;
            if (native && spec.channelformat(c) == OIIO::TypeDesc::HALF) {
              const half h(value);
              std::memcpy(to + outOffsets[c], &h, sizeof h);
            } else {
              std::memcpy(to + outOffsets[c], &value, sizeof value);
            }
          }
      }
    if (!out.write_scanlines(y0, y1, spec.z, request, outStrip.data()))
      fail(outPath, "write failed (" + firstLine(out.geterror()) + ")");
  }
}

}  // namespace

void writeImage(const std::string& path, const Image& image, bool half,
                const std::vector<std::string>& channelNames) {
  writePlain(path, image, half ? PixelType::Half : PixelType::Float, channelNames, {}, {});
}

void writeImage(const std::string& path, const Image& image, PixelType type,
                const std::vector<std::string>& channelNames) {
  writePlain(path, image, type, channelNames, {}, {});
}

WriteOptions writeOptionsFor(const FrameBuffers& frame) {
  WriteOptions options;
  options.layer = layerPrefixOf(frame) + options.layer;
  options.dataWindow = frame.dataWindow;
  options.displayWindow = frame.displayWindow;
  options.alpha = frame.alpha;
  return options;
}

void writeResult(const std::string& sourcePath, const std::string& outPath, const Image& result,
                 const WriteOptions& options, bool allowOverwriteSource) {
  std::error_code ec;
  if (!allowOverwriteSource && fs::exists(outPath, ec) && fs::equivalent(sourcePath, outPath, ec))
    fail(outPath, "is the input file; refusing to overwrite it (use --inplace)");
  if (options.rgbOnly) {
    writePlain(outPath, result, options.half ? PixelType::Half : PixelType::Float, {"R", "G", "B"},
               options.dataWindow, options.displayWindow);
    return;
  }

  auto in = openInput(sourcePath);
  ChannelTable table = scanChannels(*in, sourcePath);
  const int anchor = anchorPart(table, options, result);
  if (anchor < 0) fail(outPath, "layer '" + options.layer + "' size does not match " + sourcePath);
  const PixelWindow window = dataWindowOf(table.parts[anchor].spec);
  const auto added = addedLayers(result, options, window, outPath, sourcePath);
  const OIIO::TypeDesc resultType = options.half ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT;
  std::vector<OutputPart> parts = planOutputParts(table, added, anchor, resultType);
  for (OutputPart& part : parts) addProvenance(part.spec);

  writeAtomically(outPath, [&](const std::string& tmp) {
    auto out = createOutput(tmp, outPath);
    std::vector<OIIO::ImageSpec> specs;
    for (const auto& p : parts) specs.push_back(p.spec);
    if (!out->open(tmp, static_cast<int>(specs.size()), specs.data()))
      fail(outPath, "cannot open for writing (" + firstLine(out->geterror()) + ")");
    for (std::size_t s = 0; s < parts.size(); ++s) {
      if (s > 0 && !out->open(tmp, parts[s].spec, OIIO::ImageOutput::AppendSubimage))
        fail(outPath, "cannot add part (" + firstLine(out->geterror()) + ")");
      writePart(*in, *out, parts[s], table, added, window, sourcePath, outPath);
    }
    if (!out->close()) fail(outPath, "write failed (" + firstLine(out->geterror()) + ")");
  });
}

}  // namespace dn
