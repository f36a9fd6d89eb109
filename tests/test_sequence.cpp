// dn::temporal::Sequence on the committed Blender sequence (testdata/sequence):
// the frame it hands back is the frame as read, and each file is decoded once
// over a whole shot.
#include "doctest_torch.h"

#include <map>

#include "dn/io/buffer_io.h"
#include "dn/io/frame_pattern.h"
#include "dn/temporal/sequence.h"

using namespace dn;
using dn::temporal::Sequence;

namespace {

const std::string kShot = std::string(DN_TESTDATA) + "/sequence/spp4.#.exr";

void checkSameFrame(const FrameBuffers& given, const FrameBuffers& read) {
  CHECK(given.names() == read.names());
  for (const auto& name : read.names()) {
    CAPTURE(name);
    CHECK(given.get(name).sameShape(read.get(name)));
    CHECK(given.get(name).pixels == read.get(name).pixels);
  }
  CHECK(given.alpha.pixels == read.alpha.pixels);
  CHECK(given.sourceChannels == read.sourceChannels);
  CHECK(given.notes == read.notes);
  CHECK((given.width == read.width && given.height == read.height));
}

}  // namespace

TEST_CASE("a sequence hands each frame back as read, each file decoded once") {
  std::vector<std::string> files;
  for (int n = 1; n <= 6; ++n) files.push_back(frameFile(kShot, n));
  std::string why;
  auto shot = Sequence::plan(kShot, files, {}, why);
  REQUIRE(shot);
  std::map<std::string, int> decoded;
  const Sequence::Read read = [&](const std::string& path, const ChannelGroups& extra) {
    ++decoded[path];
    ReadOptions options;
    options.extra = extra;
    return readFrame(path, options);
  };
  // Its own result, so that only the sequence's bookkeeping is tested here.
  const Sequence::Denoise alone = [](const std::string&, const FrameBuffers& frame) {
    DenoiseResult result;
    result.color = frame.get("color");
    return result;
  };
  for (const auto& file : files) {
    CAPTURE(file);
    const FrameBuffers frame = shot->frame(file, read);
    checkSameFrame(frame, readFrame(file));
    CHECK(frame.has("albedo"));
    CHECK(frame.alpha.pixelCount() == frame.get("color").pixelCount());
    const DenoiseResult result = shot->denoise(file, frame, read, alone);
    CHECK(result.color.sameShape(frame.get("color")));
    CHECK(shot->lastStats().neighbours > 0);
  }
  for (const auto& file : files) CHECK(decoded[file] == 1);
  CHECK_THROWS_AS(shot->frame(std::string(DN_TESTDATA) + "/sequence/missing.0007.exr", read),
                  std::invalid_argument);
}
