// dn::temporal::Sequence on the committed Blender sequence (testdata/sequence):
// the frame it hands back, and the frame a neighbour's companions are made
// from, is the frame as read (but for a normal the prefilter has cleaned, then
// a guide in half floats), and each file is decoded once over a whole shot.
#include "doctest_torch.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <tuple>
#include <vector>

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
  std::unique_ptr<Sequence> plan(const temporal::SequenceSettings& settings = {}) const {
    std::string why;
    return Sequence::plan(kShot, files, settings, why);
  }
};

// Its own result, so that only the sequence's bookkeeping is tested here.
DenoiseResult asRendered(const std::string&, const FrameBuffers& frame) {
  DenoiseResult result;
  result.color = frame.get("color");
  return result;
}

// A deterministic stand-in for a denoiser: the 5x5 box mean.
Image blurred(const Image& image) {
  Image out(image.width, image.height, image.channels);
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x)
      for (int c = 0; c < image.channels; ++c) {
        double sum = 0.0;
        int count = 0;
        for (int v = std::max(0, y - 2); v <= std::min(image.height - 1, y + 2); ++v)
          for (int u = std::max(0, x - 2); u <= std::min(image.width - 1, x + 2); ++u)
            sum += image.at(u, v, c), ++count;
        out.at(x, y, c) = static_cast<float>(sum / count);
      }
  return out;
}

DenoiseResult asBlurred(const std::string&, const FrameBuffers& frame) {
  DenoiseResult result;
  result.color = blurred(frame.get("color"));
  return result;
}

// Settings where no neighbour is brought to the frame's light first.
temporal::SequenceSettings withoutRelighting() {
  temporal::SequenceSettings settings;
  settings.filter.changedLightSpread = settings.filter.changedLightMean = 1e9;
  settings.filter.driftThreshold = 0.0;
  return settings;
}

// Companions of the colour's images under `names`, denoised (blurred) as the
// colour is, alone and accumulated; `viewDependent` names one that is.
temporal::CompanionMaker blurredCompanions(std::vector<std::string> names,
                                           const std::string& viewDependent = "") {
  temporal::CompanionMaker maker;
  maker.make = [names, viewDependent](const std::string&, const FrameBuffers& frame) {
    temporal::Companions companions;
    for (const std::string& name : names) {
      companions[name].image = blurred(frame.get("color"));
      companions[name].render = frame.get("color");
      companions[name].viewDependent = name == viewDependent;
    }
    return companions;
  };
  maker.denoiseAccumulated = [](const FrameBuffers&, const std::map<std::string, Image>& renders) {
    std::map<std::string, Image> out;
    for (const auto& [name, render] : renders) out[name] = blurred(render);
    return out;
  };
  return maker;
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

TEST_CASE("every frame of a shot is filtered over as many frames as its middle ones") {
  // A side cut short by the shot's ends is made up for on the other side.
  CountedShot counted;
  temporal::SequenceSettings settings;
  settings.radius = 2;
  auto shot = counted.plan(settings);
  REQUIRE(shot);
  for (const auto& file : counted.files) {
    CAPTURE(file);
    const FrameBuffers frame = shot->frame(file, counted.read);
    shot->denoise(file, frame, counted.read, asRendered);
    CHECK(shot->lastStats().neighbours == 4);
  }
  for (const auto& file : counted.files) CHECK(counted.decoded[file] == 1);
  // Beyond twice the radius on one side, no more.
  settings.radius = 1;
  shot = counted.plan(settings);
  const std::string first = counted.files.front();
  shot->denoise(first, shot->frame(first, counted.read), counted.read, asRendered);
  CHECK(shot->lastStats().neighbours == 2);
}

// A stand-in for a denoiser with the prefilter: the render as it is, and the
// albedo and normal "cleaned" (here: as read).
DenoiseResult asRenderedCleaned(const std::string& path, const FrameBuffers& frame) {
  DenoiseResult result = asRendered(path, frame);
  result.cleanAlbedo = frame.get("albedo");
  result.cleanNormal = frame.get("normal");
  return result;
}

TEST_CASE("once cleaned, a frame's normal is held as a guide in half floats, unless asked") {
  for (const bool asRead : {false, true}) {
    CAPTURE(asRead);
    temporal::SequenceSettings settings;
    settings.framesAsRead = asRead;
    CountedShot counted;
    auto shot = counted.plan(settings);
    REQUIRE(shot);
    const std::string first = counted.files.front(), second = counted.files[1];
    shot->denoise(first, shot->frame(first, counted.read), counted.read, asRenderedCleaned);
    // The second frame, a neighbour of the first, is held denoised.
    const FrameBuffers held = shot->frame(second, counted.read);
    const FrameBuffers read = readFrame(second);
    CHECK(held.get("color").pixels == read.get("color").pixels);
    CHECK(held.get("albedo").pixels == read.get("albedo").pixels);
    const Image& normal = held.get("normal");
    REQUIRE(normal.sameShape(read.get("normal")));
    double worst = 0.0;
    for (std::size_t i = 0; i < normal.pixels.size(); ++i)
      worst = std::max(worst, std::abs(double(normal.pixels[i]) - read.get("normal").pixels[i]));
    if (asRead) {
      CHECK(normal.pixels == read.get("normal").pixels);
    } else {
      CHECK(worst > 0.0);                    // the file's normal is in floats
      CHECK(worst <= std::ldexp(1.0, -11));  // a unit vector's components in half floats
    }
  }
}

TEST_CASE("a frame denoised from the window gives the same bits as from the caller's copy") {
  // With the prefilter's stand-in, so that the accumulated renders are
  // denoised again on the frame as the window holds it.
  auto cleanedBlur = [](const std::string& path, const FrameBuffers& frame) {
    DenoiseResult result = asRenderedCleaned(path, frame);
    result.color = blurred(result.color);
    return result;
  };
  CountedShot given, fromWindow;
  auto withCopy = given.plan(), without = fromWindow.plan();
  REQUIRE((withCopy && without));
  int accumulated = 0;
  for (const auto& file : given.files) {
    CAPTURE(file);
    const FrameBuffers frame = withCopy->frame(file, given.read);
    const Image a = withCopy->denoise(file, frame, given.read, cleanedBlur).color;
    const Image b = without->denoise(file, fromWindow.read, cleanedBlur).color;
    CHECK(a.pixels == b.pixels);
    CHECK(without->lastStats().accumulatedFrames == withCopy->lastStats().accumulatedFrames);
    accumulated += without->lastStats().accumulatedFrames > 1.0;
  }
  CHECK(accumulated >= 4);
  for (const auto& file : fromWindow.files) CHECK(fromWindow.decoded[file] == 1);
}

TEST_CASE(
    "a frame's accumulated render is steered as the frame was, its noise not measured again") {
  for (const bool steered : {false, true}) {
    CAPTURE(steered);
    CountedShot counted;
    auto shot = counted.plan();
    REQUIRE(shot);
    int again = 0;
    const Sequence::Denoise denoise = [&](const std::string& path, const FrameBuffers& frame) {
      DenoiseResult result = asRenderedCleaned(path, frame);
      result.color = blurred(result.color);
      if (!frame.auxPrefiltered) {
        CHECK_FALSE(frame.correlatedNoise);  // a frame as read: for the denoiser to measure
        result.steered = steered;
        return result;
      }
      ++again;
      REQUIRE(frame.correlatedNoise);
      CHECK(*frame.correlatedNoise == steered);
      return result;
    };
    for (const auto& file : counted.files) shot->denoise(file, counted.read, denoise);
    CHECK(again >= 4);
  }
}

TEST_CASE("exactly the frames that took from their neighbours are denoised again, and -v says so") {
  CountedShot counted;
  auto shot = counted.plan();
  REQUIRE(shot);
  int again = 0, took = 0;
  const Sequence::Denoise denoise = [&](const std::string& path, const FrameBuffers& frame) {
    again += frame.auxPrefiltered;
    DenoiseResult result = asRenderedCleaned(path, frame);
    result.color = blurred(result.color);
    return result;
  };
  for (const auto& file : counted.files) {
    shot->denoise(file, counted.read, denoise);
    const bool accumulated = shot->lastStats().accumulatedFrames > 1.0;
    took += accumulated;
    CHECK((shot->report().find("denoised again") != std::string::npos) == accumulated);
  }
  CHECK(again == took);
  CHECK(took >= 4);
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

TEST_CASE("a companion made as the colour is filtered, accumulated and averaged over time as it") {
  // A companion of the colour's images, denoised (here: blurred) as the
  // colour is, alone and accumulated, takes the colour's weights at every
  // step, its past histories' mean included, so it comes out as the colour.
  // (A neighbour brought to the frame's light first brings each image by its
  // own factor, and the colour's history by its result's: none is here.) It
  // takes the colour's share of its history wherever its render gathered less
  // (a half: a float per pixel as exact as the colour's double).
  temporal::SequenceSettings settings = withoutRelighting();
  settings.filter.accumulatedShare = settings.filter.lightShareAlone = 0.5;
  CountedShot counted;
  auto shot = counted.plan(settings);
  REQUIRE(shot);
  const temporal::CompanionMaker maker = blurredCompanions({"colour"});
  int averaged = 0;
  for (const auto& file : counted.files) {
    CAPTURE(file);
    const FrameBuffers frame = shot->frame(file, counted.read);
    const auto out = shot->denoise(file, frame, counted.read, asBlurred, maker);
    const Image& colour = out.result.color;
    const Image& companion = out.companions.at("colour");
    REQUIRE(companion.sameShape(colour));
    CHECK(companion.pixels == colour.pixels);
    averaged += shot->lastStats().accumulatedFrames > 1.0;
  }
  CHECK(averaged >= 4);
}

TEST_CASE("a view-dependent companion takes the colour's weights where its surface moves") {
  // The colour's weights already fall with motion by the frame's view-dependent
  // share of its light (TemporalOptions::viewDependentMotion): a view-dependent
  // companion takes them as they are, so on the moving box it comes out as the
  // colour, its share alone in full (viewDependentShareFull at the frame's share).
  temporal::SequenceSettings settings = withoutRelighting();
  settings.viewDependentShare = [](const std::string&, const FrameBuffers& frame) {
    return Image(frame.width, frame.height, 1, 0.5f);
  };
  settings.filter.accumulatedShare = settings.filter.lightShareAlone = 0.5;
  settings.filter.viewDependentShareAlone = 0.5;
  settings.filter.viewDependentShareFull = 0.5;
  REQUIRE(settings.filter.viewDependentMotion > 0.0);
  CountedShot counted;
  auto shot = counted.plan(settings);
  REQUIRE(shot);
  const temporal::CompanionMaker maker = blurredCompanions({"colour", "glossy"}, "glossy");
  for (const auto& file : counted.files) {
    CAPTURE(file);
    const auto out =
        shot->denoise(file, shot->frame(file, counted.read), counted.read, asBlurred, maker);
    CHECK(out.companions.at("glossy").pixels == out.result.color.pixels);
  }
}

TEST_CASE("a light companion's history share follows what its render gathered") {
  // As above, the view-dependent gate off so that the glossy companion takes
  // the colour's weights: at the colour's share everywhere both come out as
  // the colour; with none where its render gathered one frame, a companion
  // differs where it gathered under two, but not where it gathered two or more.
  auto run = [](double lightAlone, double viewDependentAlone, float viewDependentLight = -1.0f) {
    temporal::SequenceSettings settings = withoutRelighting();
    if (viewDependentLight >= 0.0f)  // every frame's view-dependent share of its light
      settings.viewDependentShare = [viewDependentLight](const std::string&,
                                                         const FrameBuffers& frame) {
        return Image(frame.width, frame.height, 1, viewDependentLight);
      };
    settings.filter.viewDependentMotion = 0.0;
    settings.filter.accumulatedShare = 0.5;
    settings.filter.lightShareAlone = lightAlone;
    settings.filter.viewDependentShareAlone = viewDependentAlone;
    CountedShot counted;
    auto shot = counted.plan(settings);
    REQUIRE(shot);
    const temporal::CompanionMaker maker =
        blurredCompanions({"colour", "diffuse", "glossy"}, "glossy");
    std::map<std::string, Image> third;
    for (int n = 0; n < 3; ++n) {
      const std::string& file = counted.files[n];
      third = shot->denoise(file, shot->frame(file, counted.read), counted.read, asBlurred, maker)
                  .companions;
    }
    return third;
  };
  auto differing = [](const Image& a, const Image& b) {
    std::size_t differ = 0;
    for (std::size_t i = 0; i < a.pixels.size(); ++i) differ += a.pixels[i] != b.pixels[i];
    return differ;
  };
  const auto full = run(0.5, 0.5);
  const Image& colour = full.at("colour");
  CHECK(full.at("diffuse").pixels == colour.pixels);
  CHECK(full.at("glossy").pixels == colour.pixels);
  for (const auto& [light, viewDependent, changed, kept] :
       {std::tuple{0.0, 0.5, "diffuse", "glossy"}, std::tuple{0.5, 0.0, "glossy", "diffuse"}}) {
    CAPTURE(changed);
    const auto less = run(light, viewDependent);
    CHECK(less.at(kept).pixels == colour.pixels);
    const std::size_t differ = differing(less.at(changed), colour);
    CHECK(differ > 0);
    CHECK(differ < colour.pixels.size());
  }
  // The view-dependent share alone in full where the frame's light is view-dependent
  // (TemporalOptions::viewDependentShareFull), none where none of it is.
  CHECK(run(0.5, 0.5, 1.0f).at("glossy").pixels == colour.pixels);
  CHECK(run(0.5, 0.5, 0.0f).at("glossy").pixels == run(0.5, 0.0).at("glossy").pixels);
}
