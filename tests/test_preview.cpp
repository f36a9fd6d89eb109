// Display pictures through OpenColorIO: the built-in sRGB config against the
// sRGB curve of libtonemap, clear errors for wrong names, and the writer that
// turns a linear image into an 8-bit PNG or a 16-bit TIFF.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <string>

#include "dn/io/buffer_io.h"
#include "dn/io/preview_io.h"
#include "dn/ocio_preview.h"
#include "dn/tonemap.h"

namespace fs = std::filesystem;
using namespace dn;

namespace {

// A horizontal ramp from -0.5 to 3 (below black to far above white), grey.
Image linearRamp(int width) {
  Image image(width, 2, 3);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < width; ++x)
      for (int c = 0; c < 3; ++c)
        image.at(x, y, c) = -0.5f + 3.5f * x / (width - 1) * (1 + 0.1f * c);
  return image;
}

float expectedSrgb(float linear) { return tonemap::srgbEncode(std::clamp(linear, 0.0f, 1.0f)); }

std::string errorOf(const tonemap::PreviewOptions& options) {
  try {
    tonemap::OcioDisplay display(options);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

const char* kBlenderConfig = "/usr/share/blender/datafiles/colormanagement/config.ocio";

// Unset $OCIO for a test, restored after it.
struct NoOcioEnv {
  std::string saved;
  bool had = false;
  NoOcioEnv() {
    if (const char* v = std::getenv("OCIO")) saved = v, had = true;
    ::unsetenv("OCIO");
  }
  ~NoOcioEnv() {
    if (had) ::setenv("OCIO", saved.c_str(), 1);
  }
};

}  // namespace

TEST_CASE("the built-in config is the sRGB curve on [0, 1]") {
  NoOcioEnv noEnv;
  Image image = linearRamp(256);
  const Image linear = image;
  tonemap::OcioDisplay display;
  CHECK(display.description() == "sRGB / Standard (OCIO config built-in sRGB)");
  display.apply(image);
  float worst = 0;
  for (std::size_t i = 0; i < image.size(); ++i)
    worst = std::max(worst, std::abs(image.pixels[i] - expectedSrgb(linear.pixels[i])));
  CHECK(worst < 1e-4f);
}

TEST_CASE("$OCIO is honoured and --ocio wins over it") {
  NoOcioEnv noEnv;
  const fs::path dir = fs::temp_directory_path() / "dn_test_preview_env";
  fs::create_directories(dir);
  const std::string config = (dir / "config.ocio").string();
  {
    // The built-in config with its display renamed: which one was read shows.
    std::string text = tonemap::builtinOcioConfig();
    for (std::size_t at; (at = text.find("sRGB:")) != std::string::npos;)
      text.replace(at, 5, "Monitor:");
    for (std::size_t at; (at = text.find("[sRGB]")) != std::string::npos;)
      text.replace(at, 6, "[Monitor]");
    std::FILE* f = std::fopen(config.c_str(), "w");
    REQUIRE(f);
    std::fputs(text.c_str(), f);
    std::fclose(f);
  }
  ::setenv("OCIO", config.c_str(), 1);
  CHECK(tonemap::OcioDisplay().description() == "Monitor / Standard (OCIO config " + config + ")");
  tonemap::PreviewOptions options;
  options.config = std::string(DN_SOURCE_DIR) + "/libtonemap/ocio/srgb.ocio";
  CHECK(tonemap::OcioDisplay(options).description().rfind("sRGB / Standard", 0) == 0);
  ::unsetenv("OCIO");
  fs::remove_all(dir);
}

TEST_CASE("wrong config, display or view: one line naming what exists") {
  NoOcioEnv noEnv;
  tonemap::PreviewOptions options;
  options.view = "Filmic";
  CHECK(errorOf(options) ==
        "built-in sRGB: display 'sRGB' has no view 'Filmic' (it has: Standard, Raw)");
  options = {};
  options.display = "P3";
  CHECK(errorOf(options) == "built-in sRGB: no display 'P3' (it has: sRGB)");
  options = {};
  options.config = "/nonexistent/config.ocio";
  CHECK(errorOf(options).rfind("/nonexistent/config.ocio: not a usable OpenColorIO config", 0) ==
        0);
  options = {};
  options.source = "ACEScg";
  CHECK(errorOf(options) == "built-in sRGB: no colour space or role 'ACEScg'");
}

TEST_CASE("Blender's config: Filmic compresses highlights that Standard clips") {
  if (!fs::exists(kBlenderConfig)) return;  // Blender not installed (DN_SKIP_BLENDER)
  tonemap::PreviewOptions options;
  options.config = kBlenderConfig;
  options.view = "Filmic";
  Image image(3, 1, 3);
  image.pixels = {0.18f, 0.18f, 0.18f, 1.0f, 1.0f, 1.0f, 4.0f, 4.0f, 4.0f};
  tonemap::OcioDisplay(options).apply(image);
  CHECK(image.pixels[0] > 0.3f);  // mid grey lands mid-range
  CHECK(image.pixels[0] < 0.7f);
  CHECK(image.pixels[3] < 0.95f);  // linear 1 is not yet white
  CHECK(image.pixels[6] > image.pixels[3]);
  CHECK(image.pixels[6] < 1.0f);
}

TEST_CASE("output kinds follow the format") {
  CHECK(outputKindFor("a/b.exr") == OutputKind::Layered);
  CHECK(outputKindFor("b.EXR") == OutputKind::Layered);
  CHECK(outputKindFor("b.pfm") == OutputKind::LinearRgb);
  CHECK(outputKindFor("b.hdr") == OutputKind::LinearRgb);
  CHECK(outputKindFor("b.png") == OutputKind::Display);
  CHECK(outputKindFor("b.jpg") == OutputKind::Display);
  CHECK(outputKindFor("b.tif") == OutputKind::Display);
  CHECK(outputKindFor("b.tif", true) == OutputKind::LinearRgb);
  CHECK(outputKindFor("b.png", true) == OutputKind::Display);
}

TEST_CASE("display pictures: 8-bit PNG and 16-bit TIFF of the sRGB-encoded ramp") {
  NoOcioEnv noEnv;
  const fs::path dir = fs::temp_directory_path() / "dn_test_preview_write";
  fs::create_directories(dir);
  const Image linear = linearRamp(300);
  const tonemap::OcioDisplay display;
  for (const auto& [name, levels] : {std::pair<std::string, float>{"ramp.png", 255.0f},
                                     std::pair<std::string, float>{"ramp.tif", 65535.0f}}) {
    const std::string path = (dir / name).string();
    writeDisplayImage(path, linear, display);
    const Image back = readImage(path, 3);
    REQUIRE(back.sameShape(linear));
    float worst = 0;
    for (std::size_t i = 0; i < back.size(); ++i)
      worst = std::max(worst, std::abs(back.pixels[i] - expectedSrgb(linear.pixels[i])) * levels);
    CHECK_MESSAGE(worst <= 0.51f, name << ": " << worst << " code values off");
  }
  // The writer needs colour, and leaves nothing behind when it cannot write.
  CHECK_THROWS_AS(writeDisplayImage((dir / "grey.png").string(), Image(4, 4, 1), display), IoError);
  CHECK_THROWS_AS(writeDisplayImage((dir / "missing" / "x.png").string(), linear, display),
                  IoError);
  CHECK(std::distance(fs::directory_iterator(dir), fs::directory_iterator()) == 2);
  fs::remove_all(dir);
}
