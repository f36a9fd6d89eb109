// The .npy reader and writer (dn/io/npy.h) against files numpy saved itself
// (testdata/npy, tests/make_npy_fixtures.py): values, float16 rounding bit for
// bit, the writer's bytes equal to numpy's, and one clear line per refusal.
#include <doctest/doctest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "dn/io/npy.h"

using namespace dn;
namespace fs = std::filesystem;

namespace {

std::string fixture(const std::string& name) { return std::string(DN_TESTDATA) + "/npy/" + name; }

std::string bytesOf(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

uint32_t bitsOf(float value) {
  uint32_t bits;
  std::memcpy(&bits, &value, sizeof bits);
  return bits;
}

struct TempDir {
  fs::path path = fs::temp_directory_path() / ("dn_npy_" + std::to_string(getpid()));
  TempDir() { fs::create_directories(path); }
  ~TempDir() { fs::remove_all(path); }
  std::string operator/(const std::string& name) const { return (path / name).string(); }
};

void checkRefused(const std::string& name, const std::string& reason) {
  const std::string path = fixture(name);
  try {
    npy::readImage(path);
    FAIL("reading " << name << " did not throw");
  } catch (const npy::NpyError& e) {
    const std::string message = e.what();
    CAPTURE(message);
    CHECK(message.rfind(path + ": ", 0) == 0);
    CHECK(message.find(reason) != std::string::npos);
    CHECK(message.find('\n') == std::string::npos);
  }
}

}  // namespace

TEST_CASE("float32 images read with numpy's shape and values") {
  // numpy: (np.arange(24).reshape(2, 3, 4) - 7.5) * 0.25, C order.
  const Image image = npy::readImage(fixture("f32_image.npy"));
  CHECK(image.height == 2);
  CHECK(image.width == 3);
  CHECK(image.channels == 4);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x)
      for (int c = 0; c < 4; ++c) CHECK(image.at(x, y, c) == ((y * 3 + x) * 4 + c - 7.5f) * 0.25f);

  const Image gray = npy::readImage(fixture("f32_gray.npy"));  // linspace(-1, 1, 12).reshape(3, 4)
  CHECK(gray.channels == 1);
  CHECK(gray.height == 3);
  CHECK(gray.at(0, 0, 0) == -1.0f);
  CHECK(gray.at(3, 2, 0) == 1.0f);

  const npy::Array vector = npy::read(fixture("f32_vector.npy"));
  CHECK(vector.shape == std::vector<int64_t>{5});
  CHECK(vector.values == std::vector<float>{1, 2, 3, 4, 5});
  const npy::Array scalar = npy::read(fixture("f32_scalar.npy"));
  CHECK(scalar.shape.empty());
  CHECK(scalar.values == std::vector<float>{2.5f});
  const npy::Array v2 = npy::read(fixture("f32_v2.npy"));  // format version 2.0
  CHECK(v2.shape == std::vector<int64_t>{2, 3});
  CHECK(v2.values == std::vector<float>{0, 1, 2, 3, 4, 5});
}

TEST_CASE("float16 conversions agree with numpy's bit for bit") {
  const npy::Array source = npy::read(fixture("half_source.npy"));
  const npy::Array halves = npy::read(fixture("half_numpy.npy"));
  CHECK(source.stored == npy::DType::Float32);
  CHECK(halves.stored == npy::DType::Float16);
  REQUIRE(source.values.size() == halves.values.size());
  for (std::size_t i = 0; i < source.values.size(); ++i) {
    const float ours = npy::halfToFloat(npy::floatToHalf(source.values[i]));
    CAPTURE(i);
    CAPTURE(source.values[i]);
    if (std::isnan(halves.values[i]))
      CHECK(std::isnan(ours));
    else
      CHECK(bitsOf(ours) == bitsOf(halves.values[i]));
  }
  // Every half converts to float and back unchanged (NaNs stay NaN).
  for (uint32_t h = 0; h < 0x10000; ++h) {
    const float f = npy::halfToFloat(uint16_t(h));
    if (std::isnan(f)) continue;
    REQUIRE(npy::floatToHalf(f) == h);
  }
}

TEST_CASE("the writer's files are byte for byte numpy's, and read back") {
  TempDir dir;
  for (const char* name : {"f32_image.npy", "f32_gray.npy", "f32_vector.npy", "f32_scalar.npy"}) {
    CAPTURE(name);
    const npy::Array array = npy::read(fixture(name));
    npy::write(dir / name, array.shape, array.values);
    CHECK(bytesOf(dir / name) == bytesOf(fixture(name)));
  }
  const npy::Array source = npy::read(fixture("half_source.npy"));
  npy::write(dir / "half.npy", source.shape, source.values, npy::DType::Float16);
  CHECK(bytesOf(dir / "half.npy") == bytesOf(fixture("half_numpy.npy")));

  const Image image = npy::readImage(fixture("f16_image.npy"));
  npy::writeImage(dir / "image.npy", image);
  const Image back = npy::readImage(dir / "image.npy");
  CHECK(back.sameShape(image));
  CHECK(back.pixels == image.pixels);
  CHECK(fs::directory_iterator(dir.path) != fs::directory_iterator());
  for (const auto& entry : fs::directory_iterator(dir.path))  // no temporary files left
    CHECK(entry.path().filename().string().find(".tmp") == std::string::npos);
}

TEST_CASE("the writer refuses a shape that does not match the values, and leaves no file") {
  TempDir dir;
  CHECK_THROWS_AS(npy::write(dir / "x.npy", {2, 3}, std::vector<float>(5)), npy::NpyError);
  CHECK_FALSE(fs::exists(dir / "x.npy"));
  CHECK_THROWS_AS(npy::write(dir.path.string() + "/missing/x.npy", {1}, {1.0f}), npy::NpyError);
}

TEST_CASE("what is not float32/float16, little-endian, C order is refused in one line") {
  checkRefused("bad_big_endian.npy", "big-endian");
  checkRefused("bad_float64.npy", "dtype '<f8' is not supported");
  checkRefused("bad_int32.npy", "dtype '<i4' is not supported");
  checkRefused("bad_fortran.npy", "Fortran-ordered");
  checkRefused("bad_4d.npy", "4 dimensions");
  checkRefused("bad_truncated.npy", "(truncated)");
  checkRefused("bad_trailing.npy", "holds 100 data bytes, its shape needs 96");
  checkRefused("bad_magic.npy", "not a .npy file");
  checkRefused("no_such_file.npy", "cannot open");
}

TEST_CASE("a frame as a folder of .npy buffers: the colour required, shapes checked") {
  const fs::path dir = fs::temp_directory_path() / ("dn_npy_frame_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  auto message = [&] {
    try {
      npy::readFrameFolder(dir.string());
    } catch (const npy::NpyError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  CHECK(message() == (dir / "color.npy").string() + ": missing (the colour is required)");
  npy::writeImage((dir / "color.npy").string(), Image(6, 4, 3, 0.5f));
  npy::writeImage((dir / "albedo.npy").string(), Image(6, 4, 3, 0.25f), npy::DType::Float16);
  npy::writeImage((dir / "notes.npy").string(), Image(2, 2, 1));  // not a buffer: ignored
  const FrameBuffers frame = npy::readFrameFolder(dir.string());
  CHECK(frame.width == 6);
  CHECK(frame.height == 4);
  CHECK(frame.buffers.size() == 2);
  CHECK(frame.get("albedo").pixels.front() == 0.25f);
  npy::writeImage((dir / "normal.npy").string(), Image(5, 4, 3));
  CHECK(message() == (dir / "normal.npy").string() + ": 5x4, the colour is 6x4");
  npy::writeImage((dir / "normal.npy").string(), Image(6, 4, 1));
  CHECK(message() == (dir / "normal.npy").string() + ": 1 channels, normal has 3");
  fs::remove_all(dir);
}
