#include <doctest/doctest.h>

#include <OpenImageIO/half.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>

#include <unistd.h>

#include "dn/io/buffer_io.h"

using namespace dn;
namespace fs = std::filesystem;

namespace {

struct TempDir {
  fs::path path;
  TempDir() {
    path = fs::temp_directory_path() / ("dn_io_test_" + std::to_string(::getpid()) + "_" +
                                        std::to_string(reinterpret_cast<std::uintptr_t>(this)));
    fs::create_directories(path);
  }
  ~TempDir() { fs::remove_all(path); }
  std::string operator/(const std::string& name) const { return (path / name).string(); }
  std::size_t fileCount() const {
    return std::distance(fs::directory_iterator(path), fs::directory_iterator());
  }
};

// Channel c of pixel i carries a value that identifies both.
float code(int layer, int i, int c) { return layer + 0.01f * i + 0.001f * c; }

// A Blender-style multilayer EXR: ViewLayer.<Pass>.<Chan>, with a metadata entry.
void writeBlenderLike(const std::string& path, int w, int h,
                      const std::map<std::string, std::string>& attributes = {},
                      bool noisyImage = false) {
  std::vector<std::vector<std::string>> layers = {
      {"ViewLayer.Combined.R", "ViewLayer.Combined.G", "ViewLayer.Combined.B",
       "ViewLayer.Combined.A"},
      {"ViewLayer.Denoising Albedo.R", "ViewLayer.Denoising Albedo.G",
       "ViewLayer.Denoising Albedo.B"},
      {"ViewLayer.Denoising Normal.X", "ViewLayer.Denoising Normal.Y",
       "ViewLayer.Denoising Normal.Z"},
      {"ViewLayer.Denoising Depth.Z"},
      {"ViewLayer.GlossInd.R", "ViewLayer.GlossInd.G", "ViewLayer.GlossInd.B"},
      {"ViewLayer.roughness.X"}};
  if (noisyImage)  // with Cycles' own denoiser on, Combined is denoised
    layers.push_back({"ViewLayer.Noisy Image.R", "ViewLayer.Noisy Image.G",
                      "ViewLayer.Noisy Image.B", "ViewLayer.Noisy Image.A"});
  std::vector<std::string> names;
  for (const auto& l : layers) names.insert(names.end(), l.begin(), l.end());
  OIIO::ImageSpec spec(w, h, static_cast<int>(names.size()), OIIO::TypeDesc::FLOAT);
  spec.channelnames = names;
  spec.attribute("Note", "rendered by a test");
  for (const auto& [name, value] : attributes) spec.attribute(name, value);
  std::vector<float> pixels(static_cast<std::size_t>(w) * h * names.size());
  for (int i = 0; i < w * h; ++i) {
    int k = 0;
    for (std::size_t l = 0; l < layers.size(); ++l)
      for (std::size_t c = 0; c < layers[l].size(); ++c)
        pixels[i * names.size() + k++] = code(static_cast<int>(l), i, static_cast<int>(c));
  }
  auto out = OIIO::ImageOutput::create(path);
  REQUIRE(out);
  REQUIRE(out->open(path, spec));
  REQUIRE(out->write_image(OIIO::TypeDesc::FLOAT, pixels.data()));
  REQUIRE(out->close());
}

Image ramp(int w, int h, int c, float offset = 0.0f) {
  Image img(w, h, c);
  for (std::size_t i = 0; i < img.size(); ++i) img.pixels[i] = offset + 0.001f * i;
  return img;
}

std::string errorOf(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const IoError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("Blender multilayer buffers are found by name") {
  TempDir dir;
  writeBlenderLike(dir / "frame.exr", 4, 3);
  FrameBuffers frame = readFrame(dir / "frame.exr");
  CHECK(frame.width == 4);
  CHECK(frame.height == 3);
  CHECK(frame.names() == std::vector<std::string>{"color", "albedo", "normal", "depth",
                                                  "glossy_indirect", "roughness"});
  const Image& color = frame.get("color");
  CHECK(color.channels == 3);
  CHECK(color.at(1, 0, 0) == doctest::Approx(code(0, 1, 0)));  // R, not A
  CHECK(color.at(1, 2, 2) == doctest::Approx(code(0, 9, 2)));
  CHECK(frame.get("normal").at(3, 2, 1) == doctest::Approx(code(2, 11, 1)));
  CHECK(frame.get("depth").channels == 1);
  CHECK(frame.get("roughness").at(0, 1, 0) == doctest::Approx(code(5, 4, 0)));
  CHECK(layerPrefixOf(frame) == "ViewLayer.");
}

TEST_CASE("a render Cycles denoised itself is denoised from its Noisy Image pass") {
  TempDir dir;
  writeBlenderLike(dir / "frame.exr", 4, 3, {}, true);
  FrameBuffers frame = readFrame(dir / "frame.exr");
  CHECK(frame.get("color").at(1, 2, 2) == doctest::Approx(code(6, 9, 2)));
  CHECK(frame.get("albedo").at(1, 2, 2) == doctest::Approx(code(1, 9, 2)));
  CHECK(layerPrefixOf(frame) == "ViewLayer.");
}

TEST_CASE("the sample count Cycles records is read from the colour's view layer") {
  TempDir dir;
  writeBlenderLike(dir / "plain.exr", 2, 2);
  CHECK(readFrame(dir / "plain.exr").samplesPerPixel == 0);
  writeBlenderLike(dir / "one.exr", 2, 2, {{"cycles.ViewLayer.samples", "16"}});
  CHECK(readFrame(dir / "one.exr").samplesPerPixel == 16);
  writeBlenderLike(dir / "two.exr", 2, 2,
                   {{"cycles.Other.samples", "4"}, {"cycles.ViewLayer.samples", "64"}});
  CHECK(readFrame(dir / "two.exr").samplesPerPixel == 64);
  writeBlenderLike(dir / "ambiguous.exr", 2, 2,
                   {{"cycles.A.samples", "4"}, {"cycles.B.samples", "64"}});
  CHECK(readFrame(dir / "ambiguous.exr").samplesPerPixel == 0);
  writeBlenderLike(dir / "bad.exr", 2, 2, {{"cycles.ViewLayer.samples", "many"}});
  CHECK(readFrame(dir / "bad.exr").samplesPerPixel == 0);
}

TEST_CASE("overrides map any channels to a buffer, and 'only' limits loading") {
  TempDir dir;
  writeBlenderLike(dir / "frame.exr", 4, 3);
  ReadOptions options;
  options.overrides["albedo"] = {"ViewLayer.GlossInd.R", "ViewLayer.GlossInd.G",
                                 "ViewLayer.GlossInd.B"};
  options.only = {"color", "albedo"};
  FrameBuffers frame = readFrame(dir / "frame.exr", options);
  CHECK(frame.names() == std::vector<std::string>{"color", "albedo"});
  CHECK(frame.get("albedo").at(2, 1, 2) == doctest::Approx(code(4, 6, 2)));

  auto parsed = parseChannelOverride("normal=N.x,N.y,N.z");
  CHECK(parsed.first == "normal");
  CHECK(parsed.second == std::vector<std::string>{"N.x", "N.y", "N.z"});
  CHECK_THROWS_AS(parseChannelOverride("normal=N.x,N.y"), std::invalid_argument);
  CHECK_THROWS_AS(parseChannelOverride("nothing=R,G,B"), std::invalid_argument);
}

TEST_CASE("buffers left out of a read are read later, as a full read gives them") {
  TempDir dir;
  writeBlenderLike(dir / "frame.exr", 4, 3);
  const FrameBuffers all = readFrame(dir / "frame.exr");
  ReadOptions options;
  options.only = {"color"};
  const FrameBuffers first = readFrame(dir / "frame.exr", options);
  CHECK(first.names() == std::vector<std::string>{"color"});
  std::vector<std::string> rest = all.names();
  rest.erase(std::find(rest.begin(), rest.end(), "color"));
  CHECK(first.unread == rest);
  const FrameBuffers more = withUnread(first, {"albedo", "normal", "no_such_buffer"});
  CHECK(more.get("albedo").pixels == all.get("albedo").pixels);
  CHECK(more.get("normal").pixels == all.get("normal").pixels);
  CHECK(more.get("color").pixels == all.get("color").pixels);
  CHECK(std::find(more.unread.begin(), more.unread.end(), "albedo") == more.unread.end());
  CHECK(all.unread.empty());
}

TEST_CASE("available buffers: what readFrame would load, from the header") {
  TempDir dir;
  writeBlenderLike(dir / "frame.exr", 4, 3);
  const std::vector<std::string> all = {"color", "albedo",          "normal",
                                        "depth", "glossy_indirect", "roughness"};
  CHECK(availableBuffers(dir / "frame.exr") == all);
  CHECK(readFrame(dir / "frame.exr").names() == all);
  ReadOptions options;
  options.overrides["diffuse_direct"] = {"ViewLayer.GlossInd.R", "ViewLayer.GlossInd.G",
                                         "ViewLayer.GlossInd.B"};
  options.only = {"color"};  // ignored: the listing is of the file
  auto withOverride = availableBuffers(dir / "frame.exr", options);
  CHECK(std::find(withOverride.begin(), withOverride.end(), "diffuse_direct") !=
        withOverride.end());
  CHECK(withOverride.size() == all.size() + 1);
  options.viewLayer = "Other";
  CHECK(errorOf([&] {
          availableBuffers(dir / "frame.exr", options);
        }).find("has no view layer 'Other'") != std::string::npos);
  CHECK(errorOf([&] { availableBuffers(dir / "missing.exr"); }).find("missing.exr: no such file") !=
        std::string::npos);
}

TEST_CASE("plain RGB files and other renderers' names") {
  TempDir dir;
  Image rgb = ramp(5, 4, 3);
  writeImage(dir / "beauty.exr", rgb);
  FrameBuffers plain = readFrame(dir / "beauty.exr");
  CHECK(plain.get("color").pixels == rgb.pixels);
  CHECK(layerPrefixOf(plain) == "");

  Image aov(5, 4, 9);
  for (std::size_t i = 0; i < aov.size(); ++i) aov.pixels[i] = static_cast<float>(i);
  writeImage(dir / "aovs.exr", aov, false,
             {"R", "G", "B", "albedo.R", "albedo.G", "albedo.B", "N.X", "N.Y", "N.Z"});
  FrameBuffers frame = readFrame(dir / "aovs.exr");
  CHECK(frame.names() == std::vector<std::string>{"color", "albedo", "normal"});
  CHECK(frame.get("normal").at(0, 0, 0) == 6.0f);
}

TEST_CASE("one file per buffer, as oidnDenoise takes them") {
  TempDir dir;
  writeImage(dir / "color.pfm", ramp(6, 2, 3));
  writeImage(dir / "albedo.pfm", ramp(6, 2, 3, 1.0f));
  writeImage(dir / "normal.exr", ramp(6, 2, 3, 2.0f));
  FrameBuffers frame = readSeparateFiles({{"color", dir / "color.pfm"},
                                          {"albedo", dir / "albedo.pfm"},
                                          {"normal", dir / "normal.exr"}});
  CHECK(frame.width == 6);
  CHECK(frame.get("albedo").pixels == ramp(6, 2, 3, 1.0f).pixels);
  CHECK(frame.get("normal").pixels == ramp(6, 2, 3, 2.0f).pixels);

  writeImage(dir / "small.pfm", ramp(3, 2, 3));
  auto message = errorOf([&] {
    readSeparateFiles({{"color", dir / "color.pfm"}, {"albedo", dir / "small.pfm"}});
  });
  CHECK(message.find("small.pfm") != std::string::npos);
  CHECK(message.find("3x2") != std::string::npos);
}

TEST_CASE("bad input gives one line naming the file") {
  TempDir dir;
  auto missing = errorOf([&] { readFrame(dir / "nope.exr"); });
  CHECK(missing == dir / "nope.exr" + ": no such file");

  std::ofstream(dir / "text.exr") << "not an image at all\n";
  auto notImage = errorOf([&] { readFrame(dir / "text.exr"); });
  CHECK(notImage.rfind(dir / "text.exr", 0) == 0);
  CHECK(notImage.find('\n') == std::string::npos);

  writeBlenderLike(dir / "full.exr", 64, 64);
  auto size = fs::file_size(dir / "full.exr");
  fs::copy_file(dir / "full.exr", dir / "cut.exr");
  fs::resize_file(dir / "cut.exr", size * 2 / 3);
  auto truncated = errorOf([&] { readFrame(dir / "cut.exr"); });
  CHECK(truncated.rfind(dir / "cut.exr", 0) == 0);
  CHECK(truncated.find('\n') == std::string::npos);

  writeImage(dir / "gray.exr", ramp(4, 4, 1), false, {"Y"});
  auto noColor = errorOf([&] { readFrame(dir / "gray.exr"); });
  CHECK(noColor.find("no colour channels") != std::string::npos);

  auto absent = errorOf([&] {
    readFrame(dir / "full.exr", ReadOptions{{}, {"color", "emission"}, "", {}});
  });
  CHECK(absent == dir / "full.exr" + ": has no 'emission' buffer");

  ReadOptions wrongChannel;
  wrongChannel.overrides["albedo"] = {"diffuse.R", "diffuse.G", "diffuse.B"};
  CHECK(errorOf([&] { readFrame(dir / "full.exr", wrongChannel); }) ==
        dir / "full.exr" + ": has no channel 'diffuse.R'");
}

TEST_CASE("results are written beside every input layer, atomically") {
  TempDir dir;
  writeBlenderLike(dir / "in.exr", 8, 5);
  Image result = ramp(8, 5, 3, 3.0f);
  WriteOptions options;
  options.layer = "ViewLayer.Denoised";
  options.extraLayers["uncertainty"] = ramp(8, 5, 1);
  writeResult(dir / "in.exr", dir / "out.exr", result, options);
  CHECK(dir.fileCount() == 2);  // no temporary file left behind

  auto in = OIIO::ImageInput::open(dir / "out.exr");
  REQUIRE(in);
  const auto& spec = in->spec();
  CHECK(spec.nchannels == 15 + 3 + 1);
  CHECK(spec.get_string_attribute("Note") == "rendered by a test");
  in->close();

  CHECK(readImage(dir / "out.exr", 0,
                  {"ViewLayer.Denoised.R", "ViewLayer.Denoised.G", "ViewLayer.Denoised.B"})
            .pixels.size() == result.pixels.size());
  Image back = readImage(dir / "out.exr", 0, {"ViewLayer.Denoised.G"});
  CHECK(back.at(7, 4, 0) == doctest::Approx(result.at(7, 4, 1)).epsilon(1e-3));  // half
  FrameBuffers original = readFrame(dir / "out.exr");
  CHECK(original.get("color").at(3, 3, 0) == doctest::Approx(code(0, 27, 0)));

  options.rgbOnly = true;
  options.half = false;
  writeResult(dir / "in.exr", dir / "plain.exr", result, options);
  CHECK(readImage(dir / "plain.exr", 0).pixels == result.pixels);
}

namespace {

// Channel `name` of an EXR as stored (half or float), as raw bytes per pixel.
std::vector<unsigned char> storedBytes(const std::string& path, const std::string& name) {
  auto in = OIIO::ImageInput::open(path);
  REQUIRE(in);
  const OIIO::ImageSpec& spec = in->spec();
  const int c = spec.channelindex(name);
  REQUIRE(c >= 0);
  const OIIO::TypeDesc type = spec.channelformat(c);
  std::vector<unsigned char> bytes(spec.image_pixels() * type.size());
  REQUIRE(in->read_image(0, 0, c, c + 1, type, bytes.data()));
  return bytes;
}

}  // namespace

TEST_CASE("kept layers are written as stored: half and float channels bit for bit") {
  TempDir dir;
  const int w = 7, h = 5;
  // With an object-index channel (uint) the file goes through float, as before.
  for (const bool withIndex : {false, true}) {
    CAPTURE(withIndex);
    OIIO::ImageSpec spec(w, h, withIndex ? 6 : 5, OIIO::TypeDesc::HALF);
    spec.channelnames = {"ViewLayer.Combined.R", "ViewLayer.Combined.G", "ViewLayer.Combined.B",
                         "ViewLayer.Depth.Z", "ViewLayer.Vector.X"};
    spec.channelformats = {OIIO::TypeDesc::HALF, OIIO::TypeDesc::HALF, OIIO::TypeDesc::HALF,
                           OIIO::TypeDesc::FLOAT, OIIO::TypeDesc::HALF};
    if (withIndex) {
      spec.channelnames.push_back("ViewLayer.IndexOB.X");
      spec.channelformats.push_back(OIIO::TypeDesc::UINT);
    }
    std::vector<float> pixels(w * h * spec.nchannels);
    for (std::size_t i = 0; i < pixels.size(); ++i)
      pixels[i] = i % spec.nchannels == 5 ? float(i % 7) : 1e4f * std::sin(0.37f * i) + 1e-3f;
    const std::string input = dir / ("mixed" + std::to_string(withIndex) + ".exr");
    const std::string output = dir / ("out" + std::to_string(withIndex) + ".exr");
    {
      auto out = OIIO::ImageOutput::create(input);
      REQUIRE(out);
      REQUIRE(out->open(input, spec));
      REQUIRE(out->write_image(OIIO::TypeDesc::FLOAT, pixels.data()));
      REQUIRE(out->close());
    }
    WriteOptions options;
    options.layer = "ViewLayer.Denoised";
    const Image result = ramp(w, h, 3, 2.0f);
    writeResult(input, output, result, options);
    for (const auto& name : spec.channelnames)
      CHECK(storedBytes(output, name) == storedBytes(input, name));
    const Image denoised = readImage(
        output, 0, {"ViewLayer.Denoised.R", "ViewLayer.Denoised.G", "ViewLayer.Denoised.B"});
    for (std::size_t i = 0; i < result.pixels.size(); ++i)
      CHECK(denoised.pixels[i] == float(half(result.pixels[i])));
  }
}

TEST_CASE(
    "channel groups read into a wider window are as OpenImageIO reads them, scanlines or tiles, "
    "a channel asked for twice in both places") {
  TempDir dir;
  const float zero = 0.0f;
  const int w = 7, h = 5;
  OIIO::ImageSpec spec(w, h, 5, OIIO::TypeDesc::HALF);
  spec.x = 3, spec.y = -2;  // a data window off the origin
  spec.channelnames = {"ViewLayer.Combined.R", "ViewLayer.Combined.G", "ViewLayer.Combined.B",
                       "ViewLayer.Depth.Z", "ViewLayer.Vector.X"};
  spec.channelformats = {OIIO::TypeDesc::HALF, OIIO::TypeDesc::HALF, OIIO::TypeDesc::HALF,
                         OIIO::TypeDesc::FLOAT, OIIO::TypeDesc::FLOAT};
  std::vector<float> pixels(w * h * spec.nchannels);
  for (std::size_t i = 0; i < pixels.size(); ++i) pixels[i] = 1e4f * std::sin(0.37f * i) + 1e-3f;
  for (const bool tiled : {false, true}) {
    CAPTURE(tiled);
    if (tiled) spec.tile_width = spec.tile_height = 4;
    const std::string path = dir / (tiled ? "tiled.exr" : "scanlines.exr");
    {
      auto out = OIIO::ImageOutput::create(path);
      REQUIRE(out);
      REQUIRE(out->open(path, spec));
      REQUIRE(out->write_image(OIIO::TypeDesc::FLOAT, pixels.data()));
      REQUIRE(out->close());
    }
    // Channels out of the file's order, in a window one row and column wider
    // each way; a sequence asks for the depth both as a buffer and as a guide.
    const PixelWindow window{spec.x - 1, spec.y - 1, w + 2, h + 2};
    const std::vector<Image> read = readImages(path,
                                               {{"ViewLayer.Vector.X", "ViewLayer.Combined.G"},
                                                {"ViewLayer.Depth.Z"},
                                                {"ViewLayer.Depth.Z"}},
                                               window);
    auto reference = [&](const std::string& name) {  // OpenImageIO's own read of one channel
      auto in = OIIO::ImageInput::open(path);
      REQUIRE(in);
      const int c = in->spec().channelindex(name);
      std::vector<float> values(w * h);
      REQUIRE(in->read_image(0, 0, c, c + 1, OIIO::TypeDesc::FLOAT, values.data()));
      return values;
    };
    const std::vector<std::pair<const float*, int>> wanted = {{&read[0].pixels[0], 2},
                                                              {&read[0].pixels[1], 2},
                                                              {&read[1].pixels[0], 1},
                                                              {&read[2].pixels[0], 1}};
    const std::vector<std::string> names = {"ViewLayer.Vector.X", "ViewLayer.Combined.G",
                                            "ViewLayer.Depth.Z", "ViewLayer.Depth.Z"};
    for (std::size_t k = 0; k < names.size(); ++k) {
      CAPTURE(names[k]);
      const std::vector<float> expected = reference(names[k]);
      const auto [first, stride] = wanted[k];
      for (int y = 0; y < window.height; ++y)
        for (int x = 0; x < window.width; ++x) {
          const int fx = x - 1, fy = y - 1;  // in the data window
          const bool inside = fx >= 0 && fy >= 0 && fx < w && fy < h;
          const float value = first[(std::size_t(y) * window.width + x) * stride];
          CHECK(std::memcmp(&value, inside ? &expected[fy * w + fx] : &zero, sizeof value) == 0);
        }
    }
  }
}

TEST_CASE("the input is never overwritten and failed writes leave nothing") {
  TempDir dir;
  writeBlenderLike(dir / "in.exr", 4, 4);
  auto before = fs::file_size(dir / "in.exr");
  auto message = errorOf([&] { writeResult(dir / "in.exr", dir / "in.exr", ramp(4, 4, 3), {}); });
  CHECK(message.find("refusing to overwrite") != std::string::npos);
  CHECK(fs::file_size(dir / "in.exr") == before);

  CHECK(errorOf([&] {
          writeImage(dir / "no/such/dir/x.exr", ramp(2, 2, 3));
        }).find("output folder") != std::string::npos);
  auto wrongSize = errorOf([&] { writeResult(dir / "in.exr", dir / "o.exr", ramp(3, 4, 3), {}); });
  CHECK(wrongSize.find("size does not match") != std::string::npos);
  CHECK(dir.fileCount() == 1);
}

TEST_CASE("non-finite values are counted and zeroed") {
  Image img(2, 2, 1);
  img.pixels = {1.0f, NAN, INFINITY, -INFINITY};
  CHECK(countAndZeroNonFinite(img) == 3);
  CHECK(img.pixels == std::vector<float>{1.0f, 0.0f, 0.0f, 0.0f});
}

TEST_CASE("fitsHalf: the largest half is 65504; a sun above it needs float") {
  Image img(2, 1, 1);
  img.pixels = {-65504.0f, 65504.0f};
  CHECK(fitsHalf(img));
  img.pixels[1] = 200000.0f;  // the sun disc of Cycles' sky texture
  CHECK_FALSE(fitsHalf(img));
  img.pixels[1] = NAN;
  CHECK_FALSE(fitsHalf(img));
}
