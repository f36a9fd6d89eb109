// dn::temporal::Sequence on the committed Blender sequence (testdata/sequence):
// the frame it hands back, and the frame a neighbour's companions are made
// from, is the frame as read, and each file is decoded once over a whole shot.
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

// The shot's files, and a Read that counts the decodings of each.
struct CountedShot {
  std::vector<std::string> files;
  std::map<std::string, int> decoded;
  Sequence::Read read = [this](const std::string& path, const ChannelGroups& extra) {
    ++decoded[path];
    ReadOptions options;
    options.extra = extra;
    return readFrame(path, options);
  };
  CountedShot() {
    for (int n = 1; n <= 6; ++n) files.push_back(frameFile(kShot, n));
  }
  std::unique_ptr<Sequence> plan() const {
    std::string why;
    return Sequence::plan(kShot, files, {}, why);
  }
};

// Its own result, so that only the sequence's bookkeeping is tested here.
DenoiseResult asRendered(const std::string&, const FrameBuffers& frame) {
  DenoiseResult result;
  result.color = frame.get("color");
  return result;
}

}  // namespace

TEST_CASE("a sequence hands each frame back as read, each file decoded once") {
  CountedShot counted;
  auto shot = counted.plan();
  REQUIRE(shot);
  for (const auto& file : counted.files) {
    CAPTURE(file);
    const FrameBuffers frame = shot->frame(file, counted.read);
    checkSameFrame(frame, readFrame(file));
    CHECK(frame.has("albedo"));
    CHECK(frame.alpha.pixelCount() == frame.get("color").pixelCount());
    const DenoiseResult result = shot->denoise(file, frame, counted.read, asRendered);
    CHECK(result.color.sameShape(frame.get("color")));
    CHECK(shot->lastStats().neighbours > 0);
  }
  for (const auto& file : counted.files) CHECK(counted.decoded[file] == 1);
  const std::string unplanned = std::string(DN_TESTDATA) + "/sequence/missing.0007.exr";
  CHECK_THROWS_AS(shot->frame(unplanned, counted.read), std::invalid_argument);
}

TEST_CASE("a neighbour's companions are made from the frame as read, each file decoded once") {
  CountedShot counted;
  auto shot = counted.plan();
  REQUIRE(shot);
  temporal::CompanionMaker maker;
  int made = 0;
  maker.make = [&](const std::string& path, const FrameBuffers& frame) {
    ++made;
    checkSameFrame(frame, readFrame(path));
    temporal::Companions companions;
    companions["colour"].image = frame.get("color");
    return companions;
  };
  for (const auto& file : counted.files) {
    const FrameBuffers frame = shot->frame(file, counted.read);
    const auto out = shot->denoise(file, frame, counted.read, asRendered, maker);
    CHECK(out.companions.at("colour").sameShape(frame.get("color")));
  }
  CHECK(made == 6);
  for (const auto& file : counted.files) CHECK(counted.decoded[file] == 1);
}
