// Frame patterns (dn/io/frame_pattern.h) on testdata/sequence: the file of a
// frame, the frame of a file, ranges, and the frames present and missing.
#include <doctest/doctest.h>

#include <stdexcept>
#include <string>

#include "dn/io/buffer_io.h"
#include "dn/io/frame_pattern.h"

using namespace dn;

namespace {

const std::string kShot = std::string(DN_TESTDATA) + "/sequence/spp4.#.exr";

}  // namespace

TEST_CASE("a frame's file and a file's frame") {
  CHECK(frameFile("out.#.exr", 7) == "out.0007.exr");
  CHECK(frameFile("out.@@@.exr", 7) == "out.007.exr");
  CHECK(frameFile("out.%05d.exr", 12) == "out.00012.exr");
  CHECK(frameNumberOf("out.#.exr", "out.0012.exr") == 12);
  CHECK(!frameNumberOf("out.#.exr", "out.12.exr"));
  CHECK(!frameNumberOf("out.#.exr", "other.0012.exr"));
  CHECK_THROWS_AS(frameFile("out.exr", 1), std::invalid_argument);
  CHECK(isFramePattern(kShot));
  CHECK(!isFramePattern(frameFile(kShot, 1)));  // an existing file is a file
}

TEST_CASE("frame ranges") {
  CHECK(parseFrameRange("1-5x2") == std::vector<int>{1, 3, 5});
  CHECK(parseFrameRange("4,2") == std::vector<int>{4, 2});
  CHECK_THROWS_AS(parseFrameRange("1-10x0"), std::invalid_argument);
  CHECK_THROWS_AS(parseFrameRange("a-b"), std::invalid_argument);
  CHECK_THROWS_AS(parseFrameRange("1-1000000"), std::invalid_argument);
}

TEST_CASE("the frames of a pattern: on disk, in a range, missing") {
  const PatternFrames all = patternFrames(kShot);
  REQUIRE(all.present.size() == 6);
  CHECK(all.present.front() == std::make_pair(1, frameFile(kShot, 1)));
  CHECK(all.missing.empty());
  const PatternFrames some = patternFrames(kShot, "2-8x3");  // 2, 5, 8
  REQUIRE(some.present.size() == 2);
  CHECK(some.present[1].first == 5);
  REQUIRE(some.missing.size() == 1);
  CHECK(some.missing[0] == std::make_pair(8, frameFile(kShot, 8)));
  CHECK_THROWS_AS(patternFrames(std::string(DN_TESTDATA) + "/sequence/none.#.exr"), IoError);
}
