// Every EXR layout and renderer naming the buffer I/O reads, on small files
// written here with OpenImageIO: tiled, MIP-mapped, DWAA, border renders,
// multi-part files with parts of different sizes, Blender 5's one part per
// pass, view layers with dots, other renderers' AOV names, [0,1]-encoded
// normals, separate PFM/HDR/PNG files; and what is written back.
#include <doctest/doctest.h>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>

#include <unistd.h>

#include "dn/io/buffer_io.h"

using namespace dn;
namespace fs = std::filesystem;

namespace {

struct TempDir {
  fs::path path;
  TempDir() {
    path = fs::temp_directory_path() / ("dn_exr_test_" + std::to_string(::getpid()) + "_" +
                                        std::to_string(reinterpret_cast<std::uintptr_t>(this)));
    fs::create_directories(path);
  }
  ~TempDir() { fs::remove_all(path); }
  std::string operator/(const std::string& name) const { return (path / name).string(); }
};

// The value every test file holds for channel c of layer number `layer` at
// pixel (x, y) in file coordinates: placement errors show as wrong values.
float code(int layer, int x, int y, int c) {
  return 0.5f + layer + 0.0625f * c + 0.01f * x + 0.001f * y;
}

// One part (or the only part) of a test file.
struct PartDesc {
  std::string name;                   // part name ("" for a single-part file)
  std::vector<std::string> channels;  // full channel names
  PixelWindow data{0, 0, 8, 6};
  PixelWindow display{0, 0, 8, 6};
  int layer = 0;  // code() layer of the first channel group
  std::function<float(const std::string& channel, int x, int y, int c)> value = nullptr;
  bool half = false;
};

OIIO::ImageSpec specOf(const PartDesc& d) {
  OIIO::ImageSpec spec(d.data.width, d.data.height, int(d.channels.size()),
                       d.half ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT);
  spec.x = d.data.x, spec.y = d.data.y;
  spec.full_x = d.display.x, spec.full_y = d.display.y;
  spec.full_width = d.display.width, spec.full_height = d.display.height;
  spec.channelnames = d.channels;
  if (!d.name.empty()) spec.attribute("name", d.name);
  spec.attribute("compression", "zip");
  return spec;
}

std::vector<float> pixelsOf(const PartDesc& d) {
  std::vector<float> pixels(std::size_t(d.data.width) * d.data.height * d.channels.size());
  std::size_t i = 0;
  for (int y = d.data.y; y < d.data.y + d.data.height; ++y)
    for (int x = d.data.x; x < d.data.x + d.data.width; ++x)
      for (std::size_t c = 0; c < d.channels.size(); ++c)
        pixels[i++] = d.value ? d.value(d.channels[c], x, y, int(c)) : code(d.layer, x, y, int(c));
  return pixels;
}

void writeParts(const std::string& path, const std::vector<PartDesc>& parts) {
  std::vector<OIIO::ImageSpec> specs;
  for (const auto& p : parts) specs.push_back(specOf(p));
  auto out = OIIO::ImageOutput::create(path);
  REQUIRE(out);
  REQUIRE(out->open(path, int(specs.size()), specs.data()));
  for (std::size_t s = 0; s < parts.size(); ++s) {
    if (s > 0) REQUIRE(out->open(path, specs[s], OIIO::ImageOutput::AppendSubimage));
    REQUIRE(out->write_image(OIIO::TypeDesc::FLOAT, pixelsOf(parts[s]).data()));
  }
  REQUIRE(out->close());
}

std::vector<std::string> layerChannels(const std::string& layer,
                                       std::vector<std::string> suffixes = {"R", "G", "B"}) {
  for (auto& s : suffixes) s = layer.empty() ? s : layer + "." + s;
  return suffixes;
}

std::vector<std::string> concat(std::initializer_list<std::vector<std::string>> lists) {
  std::vector<std::string> out;
  for (const auto& l : lists) out.insert(out.end(), l.begin(), l.end());
  return out;
}

// A Blender 3.4-style single-part view layer: Combined (RGBA), albedo,
// normal, depth; channel c of the whole list carries code(layer, x, y, c).
std::vector<std::string> blenderLayer(const std::string& view) {
  return concat({layerChannels(view + ".Combined", {"R", "G", "B", "A"}),
                 layerChannels(view + ".Denoising Albedo"),
                 layerChannels(view + ".Denoising Normal", {"X", "Y", "Z"}),
                 {view + ".Denoising Depth.Z"}});
}

std::string errorOf(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const IoError& e) {
    return e.what();
  }
  return "";
}

struct FileInfo {
  std::vector<OIIO::ImageSpec> parts;
  std::vector<std::string> channels;  // all parts
};

FileInfo infoOf(const std::string& path) {
  FileInfo info;
  auto in = OIIO::ImageInput::open(path);
  REQUIRE(in);
  for (int s = 0; in->seek_subimage(s, 0); ++s) {
    info.parts.push_back(in->spec());
    for (const auto& n : in->spec().channelnames) info.channels.push_back(n);
  }
  return info;
}

std::size_t countOf(const std::vector<std::string>& names, const std::string& name) {
  return std::count(names.begin(), names.end(), name);
}

bool anyStartsWith(const std::vector<std::string>& names, const std::string& prefix) {
  return std::any_of(names.begin(), names.end(),
                     [&](const std::string& n) { return n.rfind(prefix, 0) == 0; });
}

Image constant(int w, int h, int c, float v) { return Image(w, h, c, v); }

}  // namespace

TEST_CASE("tiled, MIP-mapped and DWAA-compressed files read like scanline ones") {
  TempDir dir;
  PartDesc plain{"", blenderLayer("ViewLayer"), {0, 0, 150, 70}, {0, 0, 150, 70}};
  writeParts(dir / "scanline.exr", {plain});
  const FrameBuffers reference = readFrame(dir / "scanline.exr");

  OIIO::ImageBuf source(dir / "scanline.exr");
  SUBCASE("tiled") {
    source.set_write_tiles(64, 64);
    REQUIRE(source.write(dir / "tiled.exr"));
    REQUIRE(infoOf(dir / "tiled.exr").parts[0].tile_width == 64);
    const FrameBuffers tiled = readFrame(dir / "tiled.exr");
    CHECK(tiled.names() == reference.names());
    for (const auto& name : reference.names())
      CHECK(tiled.get(name).pixels == reference.get(name).pixels);
    CHECK(tiled.get("color").at(149, 69, 2) == doctest::Approx(code(0, 149, 69, 2)));
    CHECK(readImage(dir / "tiled.exr", 3).pixels == reference.get("color").pixels);
  }
  SUBCASE("MIP-mapped, tiled, DWAA, half") {
    OIIO::ImageSpec config;
    config.attribute("compression", "dwaa");
    config.attribute("maketx:filtername", "box");
    config.format = OIIO::TypeDesc::HALF;
    REQUIRE(OIIO::ImageBufAlgo::make_texture(OIIO::ImageBufAlgo::MakeTxTexture, source,
                                             dir / "mip.exr", config));
    const auto info = infoOf(dir / "mip.exr");
    REQUIRE(info.parts[0].tile_width > 0);
    REQUIRE(info.parts[0].get_string_attribute("compression") == "dwaa");
    auto in = OIIO::ImageInput::open(dir / "mip.exr");
    REQUIRE(in->seek_subimage(0, 1));  // a second MIP level exists
    in->close();
    const FrameBuffers mip = readFrame(dir / "mip.exr");
    CHECK(mip.width == 150);
    CHECK(mip.names() == reference.names());
    // DWAA is lossy on R, G, B; half keeps 3 digits.
    for (const auto& name : reference.names())
      for (std::size_t i = 0; i < reference.get(name).size(); i += 97)
        CHECK(mip.get(name).pixels[i] ==
              doctest::Approx(reference.get(name).pixels[i]).epsilon(0.02));
    // The result is written as a scanline file of level 0, beside every layer.
    writeResult(dir / "mip.exr", dir / "out.exr", mip.get("color"), writeOptionsFor(mip));
    const auto out = infoOf(dir / "out.exr");
    CHECK(out.parts[0].tile_width == 0);
    CHECK(countOf(out.channels, "ViewLayer.Denoised.R") == 1);
    CHECK(readFrame(dir / "out.exr").get("albedo").at(7, 3, 1) ==
          doctest::Approx(code(0, 7, 3, 5)).epsilon(0.02));
  }
}

TEST_CASE("a border render's data window is read and kept through to the output") {
  TempDir dir;
  // Border: data 8x6 at (3, 2) in a 16x12 frame; overscan: data beyond the frame.
  for (const PixelWindow data : {PixelWindow{3, 2, 8, 6}, PixelWindow{-2, -1, 20, 14}}) {
    PartDesc part{"", blenderLayer("ViewLayer"), data, {0, 0, 16, 12}};
    writeParts(dir / "border.exr", {part});
    const FrameBuffers frame = readFrame(dir / "border.exr");
    CHECK(frame.dataWindow == data);
    CHECK(frame.displayWindow == PixelWindow{0, 0, 16, 12});
    CHECK(frame.width == data.width);
    CHECK(frame.get("color").at(0, 0, 0) == doctest::Approx(code(0, data.x, data.y, 0)));
    CHECK(frame.get("depth").at(4, 5, 0) == doctest::Approx(code(0, data.x + 4, data.y + 5, 10)));

    Image result = constant(data.width, data.height, 3, 0.25f);
    WriteOptions write = writeOptionsFor(frame);
    write.layer = "ViewLayer.Denoised";
    writeResult(dir / "border.exr", dir / "out.exr", result, write);
    const auto spec = infoOf(dir / "out.exr").parts[0];
    CHECK(PixelWindow{spec.x, spec.y, spec.width, spec.height} == data);
    CHECK(PixelWindow{spec.full_x, spec.full_y, spec.full_width, spec.full_height} ==
          PixelWindow{0, 0, 16, 12});
    const Image denoised = readImage(dir / "out.exr", 0, layerChannels("ViewLayer.Denoised"));
    CHECK(denoised.pixels == result.pixels);

    WriteOptions rgb = writeOptionsFor(frame);
    rgb.rgbOnly = true;
    writeResult(dir / "border.exr", dir / "rgb.exr", result, rgb);
    const auto plain = infoOf(dir / "rgb.exr").parts[0];
    CHECK(PixelWindow{plain.x, plain.y, plain.width, plain.height} == data);
    CHECK(plain.full_width == 16);
  }
}

// A multi-part frame of 8x6: the colour, an albedo part cropped to its
// non-empty pixels, a normal part reaching beyond the frame (OpenEXR gives
// every part the same display window).
void writeDifferentSizedParts(const std::string& path) {
  PartDesc combined{"ViewLayer.Combined",
                    layerChannels("ViewLayer.Combined", {"R", "G", "B", "A"}),
                    {0, 0, 8, 6},
                    {0, 0, 8, 6},
                    0};
  PartDesc albedo{"ViewLayer.Denoising Albedo",
                  layerChannels("ViewLayer.Denoising Albedo"),
                  {2, 1, 4, 3},
                  {0, 0, 8, 6},
                  1};
  PartDesc normal{"ViewLayer.Denoising Normal",
                  layerChannels("ViewLayer.Denoising Normal", {"X", "Y", "Z"}),
                  {5, -2, 6, 4},
                  {0, 0, 8, 6},
                  2};
  writeParts(path, {combined, albedo, normal});
}

TEST_CASE("multi-part files with parts of different sizes") {
  TempDir dir;
  writeDifferentSizedParts(dir / "parts.exr");

  const FrameBuffers frame = readFrame(dir / "parts.exr");
  CHECK(frame.names() == std::vector<std::string>{"color", "albedo", "normal"});
  const Image& a = frame.get("albedo");
  CHECK(a.width == 8);
  CHECK(a.at(2, 1, 0) == doctest::Approx(code(1, 2, 1, 0)));
  CHECK(a.at(5, 3, 2) == doctest::Approx(code(1, 5, 3, 2)));
  CHECK(a.at(1, 1, 0) == 0.0f);  // outside the part's data window
  CHECK(a.at(6, 4, 1) == 0.0f);
  const Image& n = frame.get("normal");  // rows -2..1, columns 5..10 of the file
  CHECK(n.at(5, 1, 2) == doctest::Approx(code(2, 5, 1, 2)));
  CHECK(n.at(7, 0, 0) == doctest::Approx(code(2, 7, 0, 0)));
  CHECK(n.at(4, 1, 0) == 0.0f);
  CHECK(n.at(5, 2, 0) == 0.0f);

  writeResult(dir / "parts.exr", dir / "out.exr", constant(8, 6, 3, 0.5f), writeOptionsFor(frame));
  const auto out = infoOf(dir / "out.exr");
  REQUIRE(out.parts.size() == 4);  // every part kept, and the result as a part of its own
  CHECK(out.parts[1].x == 2);
  CHECK(out.parts[1].width == 4);
  CHECK(out.parts[2].y == -2);
  CHECK(out.parts[2].width == 6);
  CHECK(out.parts[3].get_string_attribute("oiio:subimagename") == "ViewLayer.Denoised");
  CHECK(out.parts[3].channelnames == layerChannels("ViewLayer.Denoised", {"R", "G", "B", "A"}));
  const FrameBuffers back = readFrame(dir / "out.exr");
  CHECK(back.get("albedo").pixels == a.pixels);
}

TEST_CASE("readImages: several channel groups in one reading, placed in the frame's window") {
  TempDir dir;
  writeDifferentSizedParts(dir / "parts.exr");
  const std::vector<std::string> rgb = layerChannels("ViewLayer.Combined", {"R", "G", "B"});
  const std::vector<std::string> alb = layerChannels("ViewLayer.Denoising Albedo");
  const FrameBuffers frame = readFrame(dir / "parts.exr");

  const std::vector<Image> both = readImages(dir / "parts.exr", {rgb, alb}, frame.dataWindow);
  REQUIRE(both.size() == 2);
  CHECK(both[0].pixels == readImage(dir / "parts.exr", 0, rgb).pixels);
  CHECK(both[1].pixels == frame.get("albedo").pixels);  // zeros outside the albedo's part
  // Without a window, the first group's part's, as readImage reads it.
  CHECK(readImages(dir / "parts.exr", {alb}).front().pixels ==
        readImage(dir / "parts.exr", 0, alb).pixels);
  CHECK(errorOf([&] {
          readImages(dir / "parts.exr", {rgb, {"ViewLayer.Nothing.R"}});
        }).find("has no channel 'ViewLayer.Nothing.R'") != std::string::npos);
}

TEST_CASE("ReadOptions::extra: channel groups read with the buffers, as readImages reads them") {
  TempDir dir;
  writeDifferentSizedParts(dir / "parts.exr");
  const std::vector<std::string> rgb = layerChannels("ViewLayer.Combined", {"R", "G", "B"});
  const std::vector<std::string> alb = layerChannels("ViewLayer.Denoising Albedo");
  ReadOptions read;
  read.only = {"color"};
  read.extra = {{"the albedo", alb}, {"red", {rgb[0]}}};
  const FrameBuffers frame = readFrame(dir / "parts.exr", read);
  CHECK(frame.names() == std::vector<std::string>{"color"});
  const std::vector<Image> alone = readImages(dir / "parts.exr", {alb, {rgb[0]}}, frame.dataWindow);
  REQUIRE(frame.extra.size() == 2);
  CHECK(frame.extra.at("the albedo").pixels == alone[0].pixels);
  CHECK(frame.extra.at("red").pixels == alone[1].pixels);
  CHECK(bufferChannels(dir / "parts.exr").at("albedo") == alb);

  read.extra = {{"missing", {"ViewLayer.Nothing.R"}}};
  CHECK(errorOf([&] { readFrame(dir / "parts.exr", read); }) ==
        dir / "parts.exr" + ": has no channel 'ViewLayer.Nothing.R'");
}

TEST_CASE("view layers: names with dots, --view-layer, and a line when ambiguous") {
  TempDir dir;
  // Blender 3.4 single-part: two view layers; the second's values differ.
  std::vector<std::string> names =
      concat({blenderLayer("ViewLayer"), blenderLayer("ViewLayer.001")});
  PartDesc part{"", names};
  part.value = [](const std::string& n, int x, int y, int c) {
    return code(n.rfind("ViewLayer.001", 0) == 0 ? 5 : 0, x, y, c % 11);
  };
  writeParts(dir / "two.exr", {part});
  CHECK(viewLayers(dir / "two.exr") == std::vector<std::string>{"ViewLayer", "ViewLayer.001"});

  const std::string ambiguous = errorOf([&] { readFrame(dir / "two.exr"); });
  CHECK(ambiguous == dir / "two.exr" +
                         ": has 2 view layers (ViewLayer, ViewLayer.001); choose one with "
                         "--view-layer NAME");
  CHECK(errorOf([&] { availableBuffers(dir / "two.exr"); }) == ambiguous);

  ReadOptions second;
  second.viewLayer = "ViewLayer.001";
  const FrameBuffers frame = readFrame(dir / "two.exr", second);
  CHECK(frame.names() == std::vector<std::string>{"color", "albedo", "normal", "depth"});
  CHECK(frame.get("color").at(3, 2, 1) == doctest::Approx(code(5, 3, 2, 1)));
  CHECK(frame.get("depth").at(3, 2, 0) == doctest::Approx(code(5, 3, 2, 10)));
  CHECK(frame.alpha.at(3, 2, 0) == doctest::Approx(code(5, 3, 2, 3)));
  CHECK(layerPrefixOf(frame) == "ViewLayer.001.");
  ReadOptions first;
  first.viewLayer = "ViewLayer";
  CHECK(readFrame(dir / "two.exr", first).get("color").at(3, 2, 1) ==
        doctest::Approx(code(0, 3, 2, 1)));
  ReadOptions wrong;
  wrong.viewLayer = "ViewLayer.002";
  CHECK(errorOf([&] { readFrame(dir / "two.exr", wrong); }) ==
        dir / "two.exr" + ": has no view layer 'ViewLayer.002' (has: ViewLayer, ViewLayer.001)");

  // Spaces, and Blender's Composite (the compositor's output) beside one view layer.
  writeParts(dir / "spaces.exr",
             {PartDesc{"",
                       concat({layerChannels("Composite.Combined"), blenderLayer("My Layer.v2")}),
                       {0, 0, 8, 6},
                       {0, 0, 8, 6},
                       1}});
  const FrameBuffers spaced = readFrame(dir / "spaces.exr");
  CHECK(layerPrefixOf(spaced) == "My Layer.v2.");
  CHECK(spaced.get("color").at(1, 1, 0) == doctest::Approx(code(1, 1, 1, 3)));
}

TEST_CASE("Blender 5: one part per pass, full pass names") {
  TempDir dir;
  const std::vector<std::string> passes = {"Combined",
                                           "Depth",
                                           "Normal",
                                           "Diffuse Direct",
                                           "Diffuse Indirect",
                                           "Diffuse Color",
                                           "Glossy Direct",
                                           "Glossy Indirect",
                                           "Glossy Color",
                                           "Transmission Direct",
                                           "Transmission Indirect",
                                           "Transmission Color",
                                           "Emission",
                                           "Environment",
                                           "Denoising Normal",
                                           "Denoising Albedo",
                                           "Denoising Depth"};
  std::vector<PartDesc> parts;
  for (std::size_t p = 0; p < passes.size(); ++p) {
    const std::string layer = "ViewLayer." + passes[p];
    std::vector<std::string> suffixes = {"R", "G", "B"};
    if (passes[p] == "Combined") suffixes.push_back("A");
    if (passes[p].find("Normal") != std::string::npos) suffixes = {"X", "Y", "Z"};
    if (passes[p].find("Depth") != std::string::npos) suffixes = {"Z"};
    PartDesc part{layer, layerChannels(layer, suffixes), {0, 0, 8, 6}, {0, 0, 8, 6}, int(p)};
    part.half = suffixes.size() != 1 && passes[p].find("Normal") == std::string::npos;
    if (passes[p].find("Normal") != std::string::npos)  // unit normals, as Cycles writes
      part.value = [](const std::string&, int x, int, int c) {
        return c == 2 ? 0.6f : c == 1 ? 0.8f * (x % 2 ? 1.0f : -1.0f) : 0.0f;
      };
    parts.push_back(part);
  }
  writeParts(dir / "b5.exr", parts);

  const FrameBuffers frame = readFrame(dir / "b5.exr");
  CHECK(frame.names() == std::vector<std::string>{"color", "albedo", "normal", "depth",
                                                  "diffuse_direct", "diffuse_indirect",
                                                  "diffuse_color", "glossy_direct",
                                                  "glossy_indirect", "glossy_color",
                                                  "transmission_direct", "transmission_indirect",
                                                  "transmission_color", "emission", "environment"});
  CHECK(frame.get("transmission_color").at(4, 2, 1) ==
        doctest::Approx(code(11, 4, 2, 1)).epsilon(1e-3));
  CHECK(frame.get("glossy_indirect").at(7, 5, 2) ==
        doctest::Approx(code(7, 7, 5, 2)).epsilon(1e-3));
  CHECK(frame.get("depth").at(1, 1, 0) == doctest::Approx(code(16, 1, 1, 0)));  // Denoising Depth
  CHECK(frame.get("normal").at(1, 0, 1) == doctest::Approx(0.8f));
  CHECK(frame.sourceChannels.at("normal").front() == "ViewLayer.Denoising Normal.X");
  CHECK(frame.notes.empty());  // Cycles' own normals: nothing assumed
  CHECK(layerPrefixOf(frame) == "ViewLayer.");

  // The result is a new part ViewLayer.Denoised with Combined's alpha; a second
  // run replaces it.
  Image first = constant(8, 6, 3, 0.25f), second = constant(8, 6, 3, 0.75f);
  WriteOptions write = writeOptionsFor(frame);
  write.layer = layerPrefixOf(frame) + "Denoised";
  writeResult(dir / "b5.exr", dir / "once.exr", first, write);
  const FrameBuffers once = readFrame(dir / "once.exr");
  WriteOptions again = writeOptionsFor(once);
  again.layer = layerPrefixOf(once) + "Denoised";
  writeResult(dir / "once.exr", dir / "twice.exr", second, again);
  const auto info = infoOf(dir / "twice.exr");
  CHECK(info.parts.size() == passes.size() + 1);
  CHECK(countOf(info.channels, "ViewLayer.Denoised.R") == 1);
  CHECK_FALSE(anyStartsWith(info.channels, "channel"));
  const Image denoised =
      readImage(dir / "twice.exr", 0, layerChannels("ViewLayer.Denoised", {"R", "G", "B", "A"}));
  CHECK(denoised.at(3, 3, 0) == 0.75f);
  CHECK(denoised.at(3, 3, 3) == doctest::Approx(code(0, 3, 3, 3)).epsilon(1e-3));  // alpha
}

TEST_CASE("re-denoising replaces the Denoised layer; --layer Combined replaces Combined") {
  TempDir dir;
  writeParts(dir / "in.exr", {PartDesc{"", blenderLayer("ViewLayer")}});
  const FrameBuffers frame = readFrame(dir / "in.exr");
  WriteOptions write = writeOptionsFor(frame);
  write.layer = "ViewLayer.Denoised";
  writeResult(dir / "in.exr", dir / "once.exr", constant(8, 6, 3, 0.25f), write);
  WriteOptions again = writeOptionsFor(readFrame(dir / "once.exr"));
  again.layer = "ViewLayer.Denoised";
  writeResult(dir / "once.exr", dir / "twice.exr", constant(8, 6, 3, 0.75f), again);
  const auto twice = infoOf(dir / "twice.exr");
  CHECK(twice.channels.size() == 11 + 4);
  CHECK(countOf(twice.channels, "ViewLayer.Denoised.A") == 1);
  CHECK_FALSE(anyStartsWith(twice.channels, "channel"));
  CHECK(readImage(dir / "twice.exr", 0, {"ViewLayer.Denoised.G"}).at(5, 5, 0) == 0.75f);
  // Alpha carried from Combined.
  CHECK(readImage(dir / "twice.exr", 0, {"ViewLayer.Denoised.A"}).at(5, 5, 0) ==
        doctest::Approx(code(0, 5, 5, 3)).epsilon(1e-3));  // half, as the result

  write.layer = "ViewLayer.Combined";
  writeResult(dir / "in.exr", dir / "combined.exr", constant(8, 6, 3, 0.5f), write);
  const auto combined = infoOf(dir / "combined.exr");
  CHECK(combined.channels.size() == 11);
  CHECK_FALSE(anyStartsWith(combined.channels, "channel"));
  CHECK(readFrame(dir / "combined.exr").get("color").at(2, 2, 0) == 0.5f);
  CHECK(readFrame(dir / "combined.exr").get("albedo").at(2, 2, 0) ==
        doctest::Approx(code(0, 2, 2, 4)));
}

TEST_CASE("other renderers' AOV names in one multichannel EXR") {
  TempDir dir;
  SUBCASE("Arnold") {
    const auto names = concat({{"R", "G", "B", "A"},
                               layerChannels("albedo"),
                               layerChannels("N"),
                               {"Z"},
                               layerChannels("diffuse_albedo"),
                               layerChannels("specular_albedo"),
                               layerChannels("emission"),
                               layerChannels("background"),
                               layerChannels("diffuse_direct"),
                               layerChannels("transmission")});
    writeParts(dir / "arnold.exr", {PartDesc{"", names}});
    const FrameBuffers frame = readFrame(dir / "arnold.exr");
    // diffuse_direct and transmission include the surface colour, unlike Cycles' passes: not taken.
    CHECK(frame.names() == std::vector<std::string>{"color", "albedo", "normal", "depth",
                                                    "diffuse_color", "glossy_color", "emission",
                                                    "environment"});
    CHECK(frame.get("depth").at(2, 3, 0) == doctest::Approx(code(0, 2, 3, 10)));
    CHECK(frame.get("glossy_color").at(2, 3, 0) == doctest::Approx(code(0, 2, 3, 14)));
    CHECK(frame.alpha.at(2, 3, 0) == doctest::Approx(code(0, 2, 3, 3)));
    CHECK(layerPrefixOf(frame) == "");
  }
  SUBCASE("Mitsuba 3 aov integrator") {
    const auto names = concat({{"R", "G", "B", "A"},
                               layerChannels("albedo"),
                               layerChannels("nn", {"X", "Y", "Z"}),
                               {"dd.y.T"}});
    writeParts(dir / "mitsuba.exr", {PartDesc{"", names}});
    const FrameBuffers frame = readFrame(dir / "mitsuba.exr");
    CHECK(frame.names() == std::vector<std::string>{"color", "albedo", "normal", "depth"});
    CHECK(frame.get("normal").at(1, 2, 2) == doctest::Approx(code(0, 1, 2, 9)));
    CHECK(frame.get("depth").at(1, 2, 0) == doctest::Approx(code(0, 1, 2, 10)));
  }
  SUBCASE("pbrt-v4 gbuffer film: the shading normal Ns, not N") {
    const auto names = concat({{"R", "G", "B"},
                               layerChannels("Albedo"),
                               layerChannels("N", {"X", "Y", "Z"}),
                               layerChannels("Ns", {"X", "Y", "Z"}),
                               layerChannels("Variance")});
    writeParts(dir / "pbrt.exr", {PartDesc{"", names}});
    const FrameBuffers frame = readFrame(dir / "pbrt.exr");
    CHECK(frame.names() == std::vector<std::string>{"color", "albedo", "normal", "color_variance"});
    CHECK(frame.sourceChannels.at("normal").front() == "Ns.X");
  }
  SUBCASE("V-Ray and Redshift: the diffuse filter is the albedo") {
    writeParts(dir / "vray.exr",
               {PartDesc{"", concat({{"R", "G", "B"},
                                     layerChannels("VRayDiffuseFilter"),
                                     layerChannels("VRayNormals", {"X", "Y", "Z"}),
                                     {"VRayZDepth.Z"}})}});
    const FrameBuffers vray = readFrame(dir / "vray.exr");
    // VRayZDepth is normalised by the depth clip, not a distance: not taken for depth.
    CHECK(vray.names() == std::vector<std::string>{"color", "albedo", "normal"});
    CHECK(vray.get("albedo").at(3, 1, 1) == doctest::Approx(code(0, 3, 1, 4)));
    writeParts(dir / "redshift.exr",
               {PartDesc{"", concat({{"R", "G", "B"},
                                     layerChannels("DiffuseFilter"),
                                     layerChannels("BumpNormals", {"X", "Y", "Z"}),
                                     {"Z"}})}});
    CHECK(readFrame(dir / "redshift.exr").names() ==
          std::vector<std::string>{"color", "albedo", "normal", "depth"});
  }
  SUBCASE("RenderMan and Karma") {
    writeParts(dir / "rman.exr", {PartDesc{"", concat({layerChannels("Ci", {"r", "g", "b"}),
                                                       {"a"},
                                                       layerChannels("albedo", {"r", "g", "b"}),
                                                       layerChannels("normal", {"r", "g", "b"}),
                                                       {"z"}})}});
    CHECK(readFrame(dir / "rman.exr").names() ==
          std::vector<std::string>{"color", "albedo", "normal", "depth"});
    CHECK(readFrame(dir / "rman.exr").alpha.at(0, 0, 0) == doctest::Approx(code(0, 0, 0, 3)));
    writeParts(dir / "karma.exr", {PartDesc{"", concat({layerChannels("C", {"R", "G", "B", "A"}),
                                                        layerChannels("albedo"),
                                                        layerChannels("N"),
                                                        {"Pz"}})}});
    const FrameBuffers karma = readFrame(dir / "karma.exr");
    CHECK(karma.names() == std::vector<std::string>{"color", "albedo", "normal", "depth"});
    CHECK(karma.get("color").at(4, 4, 2) == doctest::Approx(code(0, 4, 4, 2)));
  }
}

TEST_CASE("normals stored as (n + 1) / 2 are decoded, and the reader says so") {
  TempDir dir;
  // Unit normals n = (0.6 cos a, 0.6 sin a, 0.8), background 0.
  auto unit = [](int x, int y, int c) {
    const float a = 0.7f * x + 1.3f * y;
    const float n[3] = {0.6f * std::cos(a), 0.6f * std::sin(a), 0.8f};
    return n[c];
  };
  auto encoded = [&](const std::string& ch, int x, int y, int c) {
    if (ch.rfind("N.", 0) != 0) return code(0, x, y, c);
    if (x == 0) return 0.0f;  // background column
    return 0.5f * (unit(x, y, c - 3) + 1.0f);
  };
  const auto names = concat({{"R", "G", "B"}, layerChannels("N", {"X", "Y", "Z"})});
  PartDesc part{"", names};
  part.value = encoded;
  writeParts(dir / "encoded.exr", {part});
  const FrameBuffers frame = readFrame(dir / "encoded.exr");
  const Image& n = frame.get("normal");
  for (int c = 0; c < 3; ++c) CHECK(n.at(3, 4, c) == doctest::Approx(unit(3, 4, c)).epsilon(1e-4));
  CHECK(n.at(0, 2, 0) == 0.0f);
  REQUIRE(frame.notes.size() == 2);
  CHECK(frame.notes[0].find("stored as (n + 1) / 2") != std::string::npos);
  CHECK(frame.notes[0].find("decoded to [-1, 1]") != std::string::npos);
  CHECK(frame.notes[1] == "normal (N.X, N.Y, N.Z): taken as world-space, as Cycles writes normals");

  part.value = [&](const std::string& ch, int x, int y, int c) {
    return ch.rfind("N.", 0) == 0 ? unit(x, y, c - 3) : code(0, x, y, c);
  };
  writeParts(dir / "signed.exr", {part});
  const FrameBuffers signedFrame = readFrame(dir / "signed.exr");
  CHECK(signedFrame.get("normal").at(3, 4, 0) == doctest::Approx(unit(3, 4, 0)));
  CHECK(signedFrame.notes ==
        std::vector<std::string>{
            "normal (N.X, N.Y, N.Z): taken as world-space, as Cycles writes normals"});
}

TEST_CASE("separate files: EXR, PFM, HDR and an 8-bit PNG, half and float") {
  TempDir dir;
  Image color(6, 4, 3), albedo(6, 4, 3), normal(6, 4, 3), depth(6, 4, 1);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 6; ++x) {
      for (int c = 0; c < 3; ++c) {
        color.at(x, y, c) = 0.25f * (1 + x) + 0.5f * c + 0.1f * y;
        albedo.at(x, y, c) = 0.1f * (1 + c) + 0.05f * x;
      }
      const float a = 0.9f * x + 0.4f * y;
      normal.at(x, y, 0) = 0.8f * std::cos(a), normal.at(x, y, 1) = 0.8f * std::sin(a);
      normal.at(x, y, 2) = -0.6f;
      depth.at(x, y, 0) = 3.0f + x;
    }
  writeImage(dir / "color.hdr", color);
  writeImage(dir / "albedo.exr", albedo, /*half=*/true);
  writeImage(dir / "depth.pfm", depth);
  // An 8-bit PNG normal map: (n + 1) / 2.
  Image png = normal;
  for (float& v : png.pixels) v = 0.5f * (v + 1.0f);
  writeImage(dir / "normal.png", png);

  const FrameBuffers frame = readSeparateFiles({{"color", dir / "color.hdr"},
                                                {"albedo", dir / "albedo.exr"},
                                                {"normal", dir / "normal.png"},
                                                {"depth", dir / "depth.pfm"}});
  CHECK(frame.names() == std::vector<std::string>{"color", "albedo", "normal", "depth"});
  for (std::size_t i = 0; i < color.size(); ++i) {
    CHECK(frame.get("color").pixels[i] == doctest::Approx(color.pixels[i]).epsilon(0.01));  // RGBE
    CHECK(frame.get("albedo").pixels[i] == doctest::Approx(albedo.pixels[i]).epsilon(1e-3));
    CHECK(frame.get("normal").pixels[i] == doctest::Approx(normal.pixels[i]).epsilon(0.01));
  }
  CHECK(frame.get("depth").pixels == depth.pixels);
  CHECK(frame.notes.size() == 2);  // decoded normals, world space assumed

  // An AOV file given for one buffer: its albedo, not its beauty.
  writeParts(
      dir / "aovs.exr",
      {PartDesc{
          "", concat({{"R", "G", "B"}, layerChannels("albedo")}), {0, 0, 6, 4}, {0, 0, 6, 4}}});
  const FrameBuffers fromAov =
      readSeparateFiles({{"color", dir / "color.hdr"}, {"albedo", dir / "aovs.exr"}});
  CHECK(fromAov.get("albedo").at(2, 1, 0) == doctest::Approx(code(0, 2, 1, 3)));
}

TEST_CASE("issue 21's case: a tiled, MIP-mapped, DWAA border render with two view layers") {
  TempDir dir;
  PartDesc part{"",
                concat({blenderLayer("ViewLayer"), blenderLayer("ViewLayer.001")}),
                {40, 16, 70, 50},
                {0, 0, 160, 90}};
  part.value = [](const std::string& n, int x, int y, int c) {
    return code(n.rfind("ViewLayer.001", 0) == 0 ? 5 : 0, x, y, c % 11);
  };
  // Level 0 as rendered, then every smaller MIP level down to 1x1, which is
  // how OpenEXR stores them (same origin, sizes halved and rounded down).
  OIIO::ImageSpec spec = specOf(part);
  spec.tile_width = spec.tile_height = 16;
  spec.attribute("compression", "dwaa");
  spec.attribute("textureformat", "Plain Texture");  // OpenImageIO then writes MIP levels
  auto writer = OIIO::ImageOutput::create(dir / "in.exr");
  REQUIRE(writer->supports("mipmap"));
  REQUIRE(writer->open(dir / "in.exr", spec));
  REQUIRE(writer->write_image(OIIO::TypeDesc::FLOAT, pixelsOf(part).data()));
  for (int level = 1; (spec.width >> (level - 1)) > 1 || (spec.height >> (level - 1)) > 1;
       ++level) {
    OIIO::ImageSpec smaller = spec;
    smaller.width = std::max(1, spec.width >> level);
    smaller.height = std::max(1, spec.height >> level);
    REQUIRE(writer->open(dir / "in.exr", smaller, OIIO::ImageOutput::AppendMIPLevel));
    REQUIRE(writer->write_image(
        OIIO::TypeDesc::FLOAT,
        std::vector<float>(smaller.image_pixels() * smaller.nchannels, 9.0f).data()));
  }
  REQUIRE(writer->close());
  auto check = OIIO::ImageInput::open(dir / "in.exr");
  REQUIRE(check->seek_subimage(0, 1));
  check->close();
  const auto in = infoOf(dir / "in.exr").parts[0];
  REQUIRE(in.tile_width > 0);
  REQUIRE(in.x == 40);

  ReadOptions read;
  read.viewLayer = "ViewLayer.001";
  const FrameBuffers frame = readFrame(dir / "in.exr", read);
  CHECK(frame.dataWindow == PixelWindow{40, 16, 70, 50});
  CHECK(frame.get("color").at(10, 20, 1) == doctest::Approx(code(5, 50, 36, 1)).epsilon(0.02));
  const Image result = constant(70, 50, 3, 0.125f);
  writeResult(dir / "in.exr", dir / "out.exr", result, writeOptionsFor(frame));
  const auto out = infoOf(dir / "out.exr");
  CHECK(PixelWindow{out.parts[0].x, out.parts[0].y, out.parts[0].width, out.parts[0].height} ==
        frame.dataWindow);
  CHECK(out.parts[0].full_width == 160);
  CHECK(countOf(out.channels, "ViewLayer.001.Denoised.A") == 1);
  CHECK(readImage(dir / "out.exr", 0, {"ViewLayer.001.Denoised.B"}).at(69, 49, 0) == 0.125f);
}
