// The TZA weight-blob reader: exact values on a blob written by hand, and one
// clear error for every kind of damage.
#include <doctest/doctest.h>

#include <cmath>

#include "dn/io/tza.h"
#include "tza_writer.h"

using namespace dn;
using dn::test::makeTzaBlob;

namespace {

// 1.0, -2.0, 0.5, 65504 (half's largest), a subnormal, +Inf as half bits.
const std::vector<uint16_t> kHalves = {0x3C00, 0xC000, 0x3800, 0x7BFF, 0x0001, 0x7C00};

std::string goodBlob() {
  return makeTzaBlob({{"conv.weight", {1, 2, 1, 3}, "oihw", kHalves},
                      {"conv.bias", {1}, "x", {0x3555}}});  // 0.333251953125
}

void checkFails(const std::string& bytes, const std::string& what) {
  try {
    tza::parse(bytes, 0, "lib.so");
    FAIL("parsing did not throw");
  } catch (const tza::TzaError& e) {
    const std::string message = e.what();
    CAPTURE(message);
    CHECK(message.rfind("lib.so: ", 0) == 0);
    CHECK(message.find(what) != std::string::npos);
    CHECK(message.find('\n') == std::string::npos);
  }
}

}  // namespace

TEST_CASE("half floats convert exactly") {
  CHECK(tza::halfToFloat(0x3C00) == 1.0f);
  CHECK(tza::halfToFloat(0xC000) == -2.0f);
  CHECK(tza::halfToFloat(0x7BFF) == 65504.0f);
  CHECK(tza::halfToFloat(0x0001) == std::ldexp(1.0f, -24));
  CHECK(tza::halfToFloat(0x0400) == std::ldexp(1.0f, -14));
  CHECK(std::isinf(tza::halfToFloat(0x7C00)));
  CHECK(std::isnan(tza::halfToFloat(0x7E00)));
  CHECK(tza::halfToFloat(0x8000) == 0.0f);
}

TEST_CASE("a blob written by hand parses to its tensors") {
  const std::string bytes = goodBlob();
  const tza::Blob blob = tza::parse(bytes, 0, "lib.so");
  REQUIRE(blob.tensors.size() == 2);
  const tza::Tensor* w = blob.find("conv.weight");
  REQUIRE(w);
  CHECK(w->dims == std::vector<int64_t>{1, 2, 1, 3});
  CHECK(w->layout == "oihw");
  REQUIRE(w->values.size() == 6);
  CHECK(w->values[0] == 1.0f);
  CHECK(w->values[1] == -2.0f);
  CHECK(w->values[2] == 0.5f);
  CHECK(w->values[3] == 65504.0f);
  CHECK(std::isinf(w->values[5]));
  CHECK(blob.find("conv.bias")->values[0] == doctest::Approx(0.333251953125));
  CHECK(blob.parameterCount() == 7);
  CHECK(blob.find("missing") == nullptr);
  CHECK(blob.size == bytes.size());
}

TEST_CASE("scan finds every blob among other bytes, with its offset") {
  const std::string blob = goodBlob();
  // Stray copies of the signature that do not parse must be passed over.
  const std::string junk = std::string("\xD7\x41\x02\x00\xFF\xFF\xFF\xFF", 8) + "code";
  const std::string library = junk + blob + std::string(37, 'x') + blob + junk;
  const auto blobs = tza::scan(library, "lib.so");
  REQUIRE(blobs.size() == 2);
  CHECK(blobs[0].offset == junk.size());
  CHECK(blobs[1].offset == junk.size() + blob.size() + 37);
  CHECK(blobs[1].find("conv.weight")->values[2] == 0.5f);
  CHECK(tza::scan("no blobs here", "x").empty());
}

TEST_CASE("damaged blobs give one line naming the file and the damage") {
  const std::string good = goodBlob();
  checkFails("\xD7\x42\x02\x00" + good.substr(4), "wrong magic");
  checkFails(good.substr(0, 2) + "\x03" + good.substr(3), "version 3");
  checkFails(good.substr(0, 6), "truncated");
  checkFails(good.substr(0, good.size() - 5), "truncated");
  std::string farTable = good;
  farTable[11] = '\x7F';  // table offset far beyond the end
  checkFails(farTable, "beyond the end");
  std::string badLayout = good;
  badLayout.replace(badLayout.find("oihw"), 4, "hwio");
  checkFails(badLayout, "unknown layout 'hwio'");
  std::string badType = good;
  badType[badType.find("oihw") + 4] = 'q';
  checkFails(badType, "unknown data type 'q'");
  // A tensor whose data would run past the end of the file.
  const std::string shortData = makeTzaBlob({{"w", {4000}, "x", {0x3C00}}});
  checkFails(shortData, "beyond the end");
}
