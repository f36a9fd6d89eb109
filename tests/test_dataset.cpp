#include <doctest/doctest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>

#include <unistd.h>

#include "dn/data/dataset.h"
#include "dn/io/buffer_io.h"

using namespace dn;
using namespace dn::data;
namespace fs = std::filesystem;

namespace {

const std::vector<std::string> kChannels = {
    "ViewLayer.Combined.R",         "ViewLayer.Combined.G",         "ViewLayer.Combined.B",
    "ViewLayer.Denoising Albedo.R", "ViewLayer.Denoising Albedo.G", "ViewLayer.Denoising Albedo.B",
    "ViewLayer.Denoising Normal.X", "ViewLayer.Denoising Normal.Y", "ViewLayer.Denoising Normal.Z",
    "ViewLayer.Denoising Depth.Z"};

// A frame file whose colour is `value` everywhere, albedo 10x that, normal
// (0, 0, 1) and depth = x + 100 y (so crops and orientations are traceable).
void writeFrameFile(const std::string& path, int w, int h, float value) {
  Image img(w, h, static_cast<int>(kChannels.size()));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float* p = img.pixel(x, y);
      p[0] = p[1] = p[2] = value;
      p[3] = p[4] = p[5] = 10 * value;
      p[6] = 0, p[7] = 0, p[8] = 1;
      p[9] = x + 100.0f * y;
    }
  writeImage(path, img, false, kChannels);
}

struct TinyDataset {
  fs::path root = fs::temp_directory_path() / ("dn_dataset_test_" + std::to_string(::getpid()));
  TinyDataset(int frames, int stacks, int w = 12, int h = 10) {
    for (int f = 0; f < frames; ++f) {
      fs::path dir = root / "train" / ("scene_" + std::to_string(f)) / "frame_0";
      fs::create_directories(dir);
      for (int k = 0; k < stacks; ++k) {
        char name[32];
        std::snprintf(name, sizeof name, "spp4_%02d.exr", k);
        writeFrameFile((dir / name).string(), w, h, static_cast<float>(k + 1));
      }
      writeFrameFile((dir / "gt_a.exr").string(), w, h, 100.0f + f);
      writeFrameFile((dir / "gt_b.exr").string(), w, h, 200.0f + f);
      std::ofstream(dir / "meta.json") << "{}\n";
    }
    fs::create_directories(root / "train" / "scene_99" / "frame_0");  // unfinished: no meta.json
  }
  ~TinyDataset() { fs::remove_all(root); }
};

// Camera-space normals of a sphere centred in the image (x right, y up).
Image sphereNormals(int size) {
  Image img(size, size, 3);
  const float c = (size - 1) / 2.0f, r = size / 2.0f;
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      float nx = (x - c) / r, ny = -(y - c) / r;
      float nz = std::sqrt(std::max(0.0f, 1 - nx * nx - ny * ny));
      float* p = img.pixel(x, y);
      p[0] = nx, p[1] = ny, p[2] = nz;
    }
  return img;
}

std::vector<Orientation> allOrientations() {
  std::vector<Orientation> out;
  for (int i = 0; i < 8; ++i) out.push_back({(i & 1) != 0, (i & 2) != 0, (i & 4) != 0});
  return out;
}

double maxDifference(const Image& a, const Image& b) {
  double m = 0;
  for (std::size_t i = 0; i < a.size(); ++i)
    m = std::max(m, double(std::abs(a.pixels[i] - b.pixels[i])));
  return m;
}

}  // namespace

TEST_CASE("orientations move pixels as flips and transposes") {
  Image img(3, 2, 1);
  img.pixels = {0, 1, 2, 3, 4, 5};  // rows: [0 1 2] [3 4 5]
  CHECK(orient(img, {false, true, false}).pixels == std::vector<float>{2, 1, 0, 5, 4, 3});
  CHECK(orient(img, {false, false, true}).pixels == std::vector<float>{3, 4, 5, 0, 1, 2});
  Image t = orient(img, {true, false, false});
  CHECK(t.width == 2);
  CHECK(t.height == 3);
  CHECK(t.pixels == std::vector<float>{0, 3, 1, 4, 2, 5});
}

TEST_CASE("normals turn with the image: a centred sphere looks the same in every orientation") {
  const Image sphere = sphereNormals(9);
  for (auto o : allOrientations()) {
    CAPTURE(o.transpose);
    CAPTURE(o.flipX);
    CAPTURE(o.flipY);
    CHECK(maxDifference(orient(sphere, o, 0), sphere) < 1e-6);
    // Moving the pixels without turning the vectors would be wrong:
    if (o.transpose || o.flipX || o.flipY) CHECK(maxDifference(orient(sphere, o), sphere) > 0.5);
  }
}

TEST_CASE("the data set scan finds finished frames and their stacks") {
  TinyDataset set(3, 16);
  auto frames = scanDataset(set.root.string());
  REQUIRE(frames.size() == 3);
  CHECK(frames[0].stacks == 16);
  CHECK(frames[0].stackSpp == 4);
  CHECK(frames[0].split == "train");
  CHECK_THROWS_AS(scanDataset(set.root.string(), "test"), IoError);
}

TEST_CASE("inputs average 1, 4 or 16 stacks with aux averaged over the same selection") {
  TinyDataset set(1, 16);
  auto frames = scanDataset(set.root.string());
  SampleOptions options;
  options.aux = {"albedo", "normal", "depth"};
  options.crop = 8;
  options.augment = false;
  auto frame = FrameData::load(frames[0], options);
  std::mt19937_64 rng(5);
  std::set<float> seen4;
  for (int i = 0; i < 60; ++i) {
    Sample s = frame->draw(rng, options);
    CHECK(s.color.width == 8);
    CHECK(s.aux.channels == 7);
    const float mean = s.color.pixels[0];
    CHECK(s.aux.pixels[0] == doctest::Approx(10 * mean));   // same stacks for the aux
    CHECK(s.target.pixels[0] == doctest::Approx(150.0f));   // mean of gt_a and gt_b
    if (s.spp == 64) CHECK(mean == doctest::Approx(8.5f));  // all 16 stacks
    if (s.spp == 4) {
      seen4.insert(mean);
      CHECK(mean == std::round(mean));
    }
    if (s.spp == 16) {  // four distinct stacks of 1..16: sum in [10, 58]
      CHECK(mean * 4 >= 10 - 1e-4);
      CHECK(mean * 4 <= 58 + 1e-4);
    }
    // The crop is contiguous: depth = x + 100 y steps by 1 along a row.
    CHECK(s.aux.at(1, 0, 6) - s.aux.at(0, 0, 6) == doctest::Approx(1.0f));
  }
  CHECK(seen4.size() > 3);  // different stacks get picked
}

TEST_CASE("the cache keeps stacks as half floats: half's precision, half the bytes") {
  Image values(4, 1, 1);
  values.pixels = {0.1f, -3.14159f, 1e6f, 2e-3f};
  const Image back = HalfImage::from(values).toImage();
  CHECK(back.pixels[0] == doctest::Approx(0.1f).epsilon(1e-3));
  CHECK(back.pixels[1] == doctest::Approx(-3.14159f).epsilon(1e-3));
  CHECK(back.pixels[2] == 65504.0f);  // the largest half, not infinity
  CHECK(back.pixels[3] == doctest::Approx(2e-3f).epsilon(1e-3));

  TinyDataset set(1, 4);
  SampleOptions options;
  options.aux = {"albedo", "normal", "depth"};
  options.spp = {4, 16};
  options.crop = 8;
  auto frame = FrameData::load(scanDataset(set.root.string())[0], options);
  const std::size_t pixels = 12 * 10;
  CHECK(frame->bytes() == 4 * (3 + 7) * pixels * 2 + 3 * pixels * 4);  // stacks + float target
}

TEST_CASE("the cleansing task pairs the two ground truths, swapped at random") {
  TinyDataset set(1, 2);
  auto frames = scanDataset(set.root.string());
  SampleOptions options;
  options.task = Task::Cleanse;
  options.aux = {"albedo"};
  options.crop = 4;
  auto frame = FrameData::load(frames[0], options);
  std::mt19937_64 rng(1);
  int swapped = 0;
  for (int i = 0; i < 40; ++i) {
    Sample s = frame->draw(rng, options);
    float in = s.color.pixels[0], out = s.target.pixels[0];
    CHECK(((in == 100.0f && out == 200.0f) || (in == 200.0f && out == 100.0f)));
    CHECK(s.aux.pixels[0] == doctest::Approx(10 * in));
    swapped += in == 200.0f;
  }
  CHECK(swapped > 5);
  CHECK(swapped < 35);
}

TEST_CASE("the loader is deterministic and resumes at a sample position") {
  TinyDataset set(3, 4);
  auto frames = scanDataset(set.root.string());
  SampleOptions options;
  options.spp = {4, 16};
  options.aux = {"normal", "depth"};
  options.crop = 6;
  LoaderOptions lo;
  lo.batchSize = 4;
  lo.seed = 42;
  Loader a(frames, options, lo);
  Batch a1 = a.next(), a2 = a.next();
  CHECK(a.position() == 8);
  CHECK(a1.color.size() == 4 * 3 * 36);
  CHECK(a1.aux.size() == 4 * 4 * 36);
  Loader b(frames, options, lo, 4);  // resumed after one batch
  Batch b2 = b.next();
  CHECK(b2.color == a2.color);
  CHECK(b2.aux == a2.aux);
  CHECK(b2.target == a2.target);
  CHECK(b2.spp == a2.spp);
  CHECK(a1.color != a2.color);
}

TEST_CASE("loader errors name the frame") {
  TinyDataset set(1, 4);
  auto frames = scanDataset(set.root.string());
  SampleOptions options;  // default asks for 64 spp: 16 stacks
  LoaderOptions lo;
  Loader loader(frames, options, lo);
  try {
    loader.next();
    FAIL("expected an error");
  } catch (const IoError& e) {
    CHECK(std::string(e.what()).find("frame_0: 64 spp needs 16 stacks") != std::string::npos);
  }
}

TEST_CASE("the committed sample data set loads with every default buffer") {
  auto frames = scanDataset(DN_TESTDATA "/dataset", "train");
  REQUIRE(!frames.empty());
  SampleOptions options;
  options.spp = {4, 16};
  options.aux = dn::defaultAuxBuffers();
  options.crop = 32;
  auto frame = FrameData::load(frames[0], options);
  std::mt19937_64 rng(3);
  for (int i = 0; i < 8; ++i) {
    Sample s = frame->draw(rng, options);
    CHECK(s.aux.channels == 34);
    for (float v : s.color.pixels) REQUIRE(std::isfinite(v));
    for (float v : s.aux.pixels) REQUIRE(std::isfinite(v));
    // Averaged unit normals stay within the unit ball, whatever the orientation.
    for (std::size_t p = 0; p < s.aux.pixelCount(); ++p) {
      const float* n = &s.aux.pixels[p * 34 + 3];
      CHECK(n[0] * n[0] + n[1] * n[1] + n[2] * n[2] <= doctest::Approx(1.0f).epsilon(0.02));
    }
  }
  // The target is the mean of the two ground-truth renders (no gt_clean.exr yet).
  SampleOptions clean;
  clean.task = Task::Clean;
  clean.crop = 0;
  clean.augment = false;
  Sample t = FrameData::load(frames[0], clean)->draw(rng, clean);
  Image a = readImage(frames[0].dir + "/gt_a.exr", 3),
        b = readImage(frames[0].dir + "/gt_b.exr", 3);
  if (!std::filesystem::exists(frames[0].dir + "/gt_clean.exr"))
    CHECK(t.target.pixels[123] == doctest::Approx(0.5f * (a.pixels[123] + b.pixels[123])));
}
