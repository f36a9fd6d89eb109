#include "dn/io/buffer_io.h"
#include "dn/io/output_files.h"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
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

// Where one channel lives in a file.
struct ChannelRef {
  int subimage;
  int index;
};

// All channels of all subimages of an open file, by full name. Parts of
// multi-part files whose channels carry no layer get the part's name as layer.
struct ChannelTable {
  std::map<std::string, ChannelRef> byName;
  std::vector<OIIO::ImageSpec> specs;
  std::vector<std::string> viewLayers;  // first components of "V.Layer.C" names
};

std::unique_ptr<OIIO::ImageInput> openInput(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) fail(path, "no such file");
  if (fs::is_directory(path, ec)) fail(path, "is a directory, not an image");
  auto in = OIIO::ImageInput::open(path);
  if (!in) fail(path, "cannot read as an image (" + firstLine(OIIO::geterror()) + ")");
  return in;
}

ChannelTable scanChannels(OIIO::ImageInput& in, const std::string& path) {
  ChannelTable table;
  for (int s = 0; in.seek_subimage(s, 0); ++s) {
    const OIIO::ImageSpec& spec = in.spec();
    if (s > 0 && (spec.width != table.specs[0].width || spec.height != table.specs[0].height))
      continue;  // a part of another size (e.g. a preview) is not a buffer of this frame
    std::string part = spec.get_string_attribute("oiio:subimagename");
    for (int c = 0; c < spec.nchannels; ++c) {
      std::string name = spec.channelnames[c];
      if (s > 0 && name.find('.') == std::string::npos && !part.empty()) name = part + "." + name;
      table.byName.emplace(name, ChannelRef{s, c});
      auto first = name.find('.');
      if (first != std::string::npos && name.find('.', first + 1) != std::string::npos) {
        std::string view = name.substr(0, first);
        if (std::find(table.viewLayers.begin(), table.viewLayers.end(), view) ==
            table.viewLayers.end())
          table.viewLayers.push_back(view);
      }
    }
    table.specs.push_back(spec);
  }
  if (table.specs.empty()) fail(path, "has no readable image");
  return table;
}

const std::vector<std::vector<std::string>>& suffixSets(int channels) {
  static const std::vector<std::vector<std::string>> rgb = {
      {"R", "G", "B"}, {"X", "Y", "Z"}, {"r", "g", "b"}, {"x", "y", "z"}};
  static const std::vector<std::vector<std::string>> scalar = {{"Z"}, {"V"}, {"X"}, {"R"}, {"Y"}};
  return channels == 3 ? rgb : scalar;
}

// Finds the channel names of a canonical buffer, or an empty list.
std::vector<std::string> resolveChannels(const ChannelTable& table, const BufferSpec& spec,
                                         const std::string& viewLayer) {
  std::vector<std::string> prefixes;
  if (!viewLayer.empty()) prefixes.push_back(viewLayer + ".");
  for (const auto& v : table.viewLayers)
    if (v != viewLayer) prefixes.push_back(v + ".");
  prefixes.push_back("");

  for (const auto& layer : spec.layers) {
    for (const auto& prefix : prefixes) {
      std::string base = layer.empty() ? prefix : prefix + layer + ".";
      if (layer.empty() && !prefix.empty()) continue;  // plain R,G,B means no layer at all
      if (spec.channels == 1 && !layer.empty() && table.byName.count(prefix + layer))
        return {prefix + layer};  // a bare scalar channel such as "Z"
      for (const auto& suffixes : suffixSets(spec.channels)) {
        std::vector<std::string> names;
        for (const auto& s : suffixes)
          if (table.byName.count(base + s)) names.push_back(base + s);
        if (names.size() == suffixes.size()) return names;
      }
    }
  }
  return {};
}

// Reads the named channels into one interleaved float image, strip by strip.
Image readChannels(OIIO::ImageInput& in, const ChannelTable& table, const std::string& path,
                   const std::vector<std::string>& names) {
  std::vector<ChannelRef> refs;
  for (const auto& n : names) {
    auto it = table.byName.find(n);
    if (it == table.byName.end()) fail(path, "has no channel '" + n + "'");
    refs.push_back(it->second);
  }
  const OIIO::ImageSpec& spec0 = table.specs[0];
  Image image(spec0.width, spec0.height, static_cast<int>(names.size()));

  // Group by subimage; read each subimage's covering channel range once per strip.
  std::set<int> subimages;
  for (const auto& r : refs) subimages.insert(r.subimage);
  for (int s : subimages) {
    int lo = INT32_MAX, hi = -1;
    for (const auto& r : refs)
      if (r.subimage == s) lo = std::min(lo, r.index), hi = std::max(hi, r.index);
    const int span = hi - lo + 1;
    if (!in.seek_subimage(s, 0)) fail(path, "cannot seek to part " + std::to_string(s));
    const OIIO::ImageSpec& spec = in.spec();
    std::vector<float> strip(static_cast<std::size_t>(spec.width) * kStripRows * span);
    for (int y0 = 0; y0 < spec.height; y0 += kStripRows) {
      int y1 = std::min(spec.height, y0 + kStripRows);
      if (!in.read_scanlines(s, 0, spec.y + y0, spec.y + y1, 0, lo, hi + 1, OIIO::TypeDesc::FLOAT,
                             strip.data()))
        fail(path, "corrupt or truncated image data (" + firstLine(in.geterror()) + ")");
      for (std::size_t k = 0; k < refs.size(); ++k) {
        if (refs[k].subimage != s) continue;
        const int offset = refs[k].index - lo;
        for (int y = y0; y < y1; ++y)
          for (int x = 0; x < spec.width; ++x)
            image.at(x, y, static_cast<int>(k)) =
                strip[(static_cast<std::size_t>(y - y0) * spec.width + x) * span + offset];
      }
    }
  }
  return image;
}

std::string joined(const std::vector<std::string>& items) {
  std::string out;
  for (const auto& i : items) out += (out.empty() ? "" : ", ") + i;
  return out;
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

// Every canonical buffer the file holds (in canonical order) with its channels:
// the overrides, else the names found in the chosen view layer.
std::vector<std::pair<std::string, std::vector<std::string>>> locateBuffers(
    const ChannelTable& table, const std::string& path, const ReadOptions& options) {
  if (!options.viewLayer.empty() && std::find(table.viewLayers.begin(), table.viewLayers.end(),
                                              options.viewLayer) == table.viewLayers.end())
    fail(path,
         "has no view layer '" + options.viewLayer + "' (has: " + joined(table.viewLayers) + ")");
  std::vector<std::pair<std::string, std::vector<std::string>>> located;
  for (const auto& spec : canonicalBuffers()) {
    auto override = options.overrides.find(spec.name);
    std::vector<std::string> names = override != options.overrides.end()
                                         ? override->second
                                         : resolveChannels(table, spec, options.viewLayer);
    if (!names.empty()) located.emplace_back(spec.name, std::move(names));
  }
  return located;
}

}  // namespace

std::vector<std::string> availableBuffers(const std::string& path, const ReadOptions& options) {
  auto in = openInput(path);
  std::vector<std::string> names;
  for (const auto& [name, channels] : locateBuffers(scanChannels(*in, path), path, options))
    names.push_back(name);
  return names;
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

FrameBuffers readFrame(const std::string& path, const ReadOptions& options) {
  auto in = openInput(path);
  ChannelTable table = scanChannels(*in, path);
  FrameBuffers frame;
  frame.width = table.specs[0].width;
  frame.height = table.specs[0].height;
  for (const auto& [name, channels] : locateBuffers(table, path, options)) {
    bool wanted = options.only.empty() ||
                  std::find(options.only.begin(), options.only.end(), name) != options.only.end();
    if (!wanted) continue;
    frame.buffers[name] = readChannels(*in, table, path, channels);
    frame.sourceChannels[name] = channels;
  }
  if (!frame.has("color")) {
    std::vector<std::string> all;
    for (const auto& [name, ref] : table.byName) all.push_back(name);
    if (all.size() > 12) all.resize(12), all.push_back("...");
    fail(path, "no colour channels found (looked for Combined.RGB, R,G,B, rgba, beauty; file has " +
                   joined(all) + "); map them with --channels color=R,G,B");
  }
  for (const auto& name : options.only)
    if (!frame.has(name)) fail(path, "has no '" + name + "' buffer");
  frame.samplesPerPixel = recordedSamples(table.specs[0], layerPrefixOf(frame));
  return frame;
}

std::vector<std::string> channelNames(const std::string& path) {
  auto in = openInput(path);
  ChannelTable table = scanChannels(*in, path);
  std::vector<std::string> names;
  for (const auto& [name, ref] : table.byName) names.push_back(name);
  return names;
}

Image readImage(const std::string& path, int channels, const std::vector<std::string>& names) {
  auto in = openInput(path);
  ChannelTable table = scanChannels(*in, path);
  std::vector<std::string> wanted = names;
  if (wanted.empty()) {
    const auto& spec = table.specs[0];
    int n = channels <= 0 ? spec.nchannels : channels;
    if (spec.nchannels < n)
      fail(path, "has " + std::to_string(spec.nchannels) + " channels, needs " + std::to_string(n));
    if (n == 3 && spec.nchannels > 3) {  // prefer the colour of a multilayer file
      FrameBuffers frame = readFrame(path, ReadOptions{{}, {"color"}, ""});
      return frame.buffers.at("color");
    }
    for (int c = 0; c < n; ++c) wanted.push_back(spec.channelnames[c]);
  }
  return readChannels(*in, table, path, wanted);
}

FrameBuffers readSeparateFiles(const std::map<std::string, std::string>& fileForBuffer) {
  auto color = fileForBuffer.find("color");
  if (color == fileForBuffer.end()) throw IoError("(arguments): a colour image is required");
  FrameBuffers frame;
  frame.buffers["color"] = readImage(color->second, 3);
  frame.width = frame.buffers["color"].width;
  frame.height = frame.buffers["color"].height;
  for (const auto& [buffer, path] : fileForBuffer) {
    if (buffer == "color") continue;
    const BufferSpec* spec = findBufferSpec(buffer);
    if (!spec) fail(path, "unknown buffer name '" + buffer + "'");
    Image image = readImage(path, spec->channels);
    if (image.width != frame.width || image.height != frame.height)
      fail(path, "is " + std::to_string(image.width) + "x" + std::to_string(image.height) +
                     " but the colour image is " + std::to_string(frame.width) + "x" +
                     std::to_string(frame.height));
    frame.buffers[buffer] = std::move(image);
  }
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

void writeImage(const std::string& path, const Image& image, bool half,
                const std::vector<std::string>& channelNames) {
  if (image.empty()) fail(path, "refusing to write an empty image");
  writeAtomically(path, [&](const std::string& tmp) {
    if (hasExtension(path, ".pfm")) return writePfm(tmp, path, image);
    auto out = createOutput(tmp, path);
    OIIO::ImageSpec spec(image.width, image.height, image.channels,
                         half ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT);
    if (!channelNames.empty()) spec.channelnames = channelNames;
    addProvenance(spec);
    if (!out->open(tmp, spec) || !out->write_image(OIIO::TypeDesc::FLOAT, image.pixels.data()) ||
        !out->close())
      fail(path, "write failed (" + firstLine(out->geterror()) + ")");
  });
}

void writeResult(const std::string& sourcePath, const std::string& outPath, const Image& result,
                 const WriteOptions& options, bool allowOverwriteSource) {
  std::error_code ec;
  if (!allowOverwriteSource && fs::exists(outPath, ec) && fs::equivalent(sourcePath, outPath, ec))
    fail(outPath, "is the input file; refusing to overwrite it (use --inplace)");
  if (options.rgbOnly) {
    writeImage(outPath, result, options.half, {"R", "G", "B"});
    return;
  }

  auto in = openInput(sourcePath);
  ChannelTable table = scanChannels(*in, sourcePath);
  const OIIO::TypeDesc resultType = options.half ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT;

  // Output part 0: every source channel, then the result and the extra layers.
  std::vector<std::pair<std::string, const Image*>> added = {{options.layer, &result}};
  for (const auto& [name, image] : options.extraLayers) added.emplace_back(name, &image);
  std::vector<OIIO::ImageSpec> specs = table.specs;
  OIIO::ImageSpec& main = specs[0];
  if (main.channelformats.empty()) main.channelformats.assign(main.nchannels, main.format);
  const int sourceChannels = main.nchannels;
  for (const auto& [layer, image] : added) {
    if (image->width != main.width || image->height != main.height)
      fail(outPath, "layer '" + layer + "' size does not match " + sourcePath);
    static const char* rgb[] = {"R", "G", "B", "A"};
    for (int c = 0; c < image->channels; ++c) {
      std::string suffix = image->channels <= 4 ? rgb[c] : std::to_string(c);
      if (image->channels == 1) suffix = "Y";
      main.channelnames.push_back(layer + "." + suffix);
      main.channelformats.push_back(resultType);
    }
    main.nchannels += image->channels;
  }
  main.alpha_channel = -1;
  main.z_channel = -1;
  addProvenance(main);

  writeAtomically(outPath, [&](const std::string& tmp) {
    auto out = createOutput(tmp, outPath);
    if (!out->open(tmp, static_cast<int>(specs.size()), specs.data()))
      fail(outPath, "cannot open for writing (" + firstLine(out->geterror()) + ")");
    for (std::size_t s = 0; s < specs.size(); ++s) {
      const OIIO::ImageSpec& spec = specs[s];
      if (s > 0 && !out->open(tmp, spec, OIIO::ImageOutput::AppendSubimage))
        fail(outPath, "cannot add part (" + firstLine(out->geterror()) + ")");
      const int inChannels = s == 0 ? sourceChannels : spec.nchannels;
      std::vector<float> inStrip(static_cast<std::size_t>(spec.width) * kStripRows * inChannels);
      std::vector<float> outStrip(static_cast<std::size_t>(spec.width) * kStripRows *
                                  spec.nchannels);
      for (int y0 = 0; y0 < spec.height; y0 += kStripRows) {
        int y1 = std::min(spec.height, y0 + kStripRows);
        if (!in->read_scanlines(static_cast<int>(s), 0, spec.y + y0, spec.y + y1, 0, 0, inChannels,
                                OIIO::TypeDesc::FLOAT, inStrip.data()))
          fail(sourcePath, "corrupt or truncated image data (" + firstLine(in->geterror()) + ")");
        for (int y = y0; y < y1; ++y)
          for (int x = 0; x < spec.width; ++x) {
            std::size_t row = static_cast<std::size_t>(y - y0) * spec.width + x;
            float* dst = &outStrip[row * spec.nchannels];
            std::copy_n(&inStrip[row * inChannels], inChannels, dst);
            int c = inChannels;
            if (s == 0)
              for (const auto& [layer, image] : added)
                for (int k = 0; k < image->channels; ++k) dst[c++] = image->at(x, y, k);
          }
        if (!out->write_scanlines(spec.y + y0, spec.y + y1, 0, OIIO::TypeDesc::FLOAT,
                                  outStrip.data()))
          fail(outPath, "write failed (" + firstLine(out->geterror()) + ")");
      }
    }
    if (!out->close()) fail(outPath, "write failed (" + firstLine(out->geterror()) + ")");
  });
}

}  // namespace dn
