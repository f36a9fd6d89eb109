// Filtering denoised frames over time: each frame's result averaged with its
// neighbours' results brought into it along the motion, where they are trusted.
// Each frame's leftover error (blotches) changes with the noise seed, so the
// average of trusted neighbours removes part of it and most of the flicker.
// What every frame's network misses alike (a faint bounce of light, glossy
// detail) no average of results brings back; the noisy renders, accumulated
// with the same weights, hold it. Denoised once more, that estimate has errors
// of its own, which change from frame to frame as the window slides (flicker):
// where the surface stands still it is averaged with the past frames' own, as
// the results are (historyMean), and a blend of the two beats either
// (blendWithHistory).
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "dn/image.h"
#include "dn/motion/motion.h"
#include "dn/motion/reproject.h"
#include "dn/temporal/learned_trust.h"
#include "dn/temporal/window_image.h"

namespace dn::temporal {

// A frame's albedo, normal and depth as the window holds them.
struct WindowGuides {
  WindowImage albedo, normal, depth;
  WindowGuides() = default;
  WindowGuides(motion::Guides guides)  // held in floats, as given
      : albedo(std::move(guides.albedo)),
        normal(std::move(guides.normal)),
        depth(std::move(guides.depth)) {}
  // The guides where held in floats, those packed unpacked into `scratch`.
  motion::GuideImages view(motion::Guides& scratch) const {
    return {&albedo.floats(scratch.albedo), &normal.floats(scratch.normal),
            &depth.floats(scratch.depth)};
  }
};

// A frame's motion as the window holds it.
struct WindowMotion {
  WindowImage toPrevious, toNext;
  std::string source;
  bool mirrored = false;
  WindowMotion() = default;
  WindowMotion(motion::MotionField field)  // held in floats, as given
      : toPrevious(std::move(field.toPrevious)),
        toNext(std::move(field.toNext)),
        source(std::move(field.source)),
        mirrored(field.mirrored) {}
  bool empty() const { return toPrevious.empty() || toNext.empty(); }
  motion::MotionField toField() const {
    return {toPrevious.toImage(), toNext.toImage(), source, mirrored};
  }
};

// One frame of the window: the denoised result, the noisy render (for the
// noise level, the light and the repeated-noise tests), its guides and motion.
// A sequence holds them in half floats where it can (Sequence); the filtered
// result is in floats.
struct WindowFrame {
  WindowImage denoised;  // 3 channels, linear
  WindowImage noisy;     // 3 channels, linear
  // Its accumulated render, denoised (TemporalResult::history, denoised);
  // empty until made. The past frames' are averaged into the frame's own.
  WindowImage history;
  WindowGuides guides;
  WindowMotion motion;
  // Per pixel, the share of the render's light that moves with the view, not
  // the surface (reflected and refracted: a renderer's glossy and
  // transmission passes); 1 channel in [0, 1], empty where unknown.
  WindowImage viewDependent;
};

// What the learned trust sees of a frame's neighbours, for fitting it
// (experiments/temporal_trust/): each neighbour the whole-frame tests kept.
struct TrustSamples {
  Image own;                                 // the frame's result
  double scale = 1.0;                        // its autoexposure
  std::vector<std::size_t> frames;           // per neighbour: its index in the window
  std::vector<Image> moved;                  // its result brought into the frame
  std::vector<std::vector<float>> features;  // per pixel, kTrustFeatureCount (learned_trust.h)
  std::vector<std::vector<double>> weights;  // per pixel, the weight the filter gave it
};

struct TemporalOptions {
  int radius = 4;  // neighbours on each side
  motion::TrustOptions trust;
  // A neighbour whose reprojected result differs from the reference (in a
  // Reinhard space, relative to the render's local noise level) by more than
  // this many robust spreads of such differences is a moving shadow or
  // highlight: its weight falls linearly to 0 between colourLow and colourHigh.
  double colourLow = 2.5;
  double colourHigh = 5.0;
  // What the colour test compares with: the frame's own result (0), the mean
  // of it and every neighbour the surface and light tests kept (1), or a
  // blend. Against its own result alone, a frame rejects its neighbours just
  // where its leftover error is largest, which they would have averaged out.
  double colourReference = 0.75;
  // The spread is at most this: on the locked-off and moving-camera shots of
  // experiments/render_sequences.py it is 0.16-0.20 at 4 spp and 0.21-0.26 at
  // 16 spp; a lamp moving across the room raises it to 1-7.
  double maxSpread = 0.3;
  // A spread above this means the light changed over most of the frame (on
  // the moving-lamp shot, filtering with the per-pixel tests alone left frames
  // up to 0.3 dB worse than alone). The neighbour is relit: each pixel scaled
  // by the ratio of the frame's and its results' means over the
  // (2 relightBox + 1)^2 box around, which leaves it only its detail within
  // the box; the renders' light test is then skipped. Still above it, the
  // neighbour is left out whole.
  double changedLightSpread = 0.6;
  // The sun moving sweeps shadows over much of the frame by a few pixels a
  // frame: per pixel too faint for the light test, yet the neighbour is
  // relit, not filtered, once its renders' light test (below) averages more
  // than this many standard errors over the frame. Where only noise differs
  // the mean is 1.2-1.3 (on every shot of experiments/shots/SPLIT_1080.md);
  // on the sweeping sun's tuning shot, 2.5-12. Any of 1.4-3 chose alike there.
  double changedLightMean = 2.0;
  // Relighting's box, 3x3. At 1080p pixel scale 5x5 let relit neighbours
  // average wider blotches and gained on the dimmer of SPLIT_1080.md's tuning
  // half, but haloed a spotlight's edge as it swept a room (held out: a frame
  // 6.6 dB worse).
  int relightBox = 1;
  // Relighting takes a pixel only where the boxes' light differs by at most
  // this factor either way: beyond it a lamp's pool arrived or left, and a
  // factor clamped to the range brought the wrong light (a held-out shot's
  // torch lost 4 dB in its direct-light pass). 10 (the clamp before) and 4
  // chose alike on the tuning half; 2 lost 0.01 dB.
  double relightRange = 10.0;
  // A light drifting slowly over part of the frame (a lamp's pool edging
  // across a wall) changes a pixel too little between frames for the tests
  // above at a few samples, yet a neighbour taken where it passes them
  // carries its older light into the frame. After the tests, each neighbour
  // not relit is brought to the frame's light wherever its taken pixels'
  // mean over the (2 driftBox + 1)^2 box around differs from the frame's by
  // more than driftThreshold (relative, the channels summed): scaled by the
  // boxes' ratio per channel (clamped to [1/2, 2]), its weights unchanged.
  // 0: off. The tuning half of experiments/shots/SPLIT_1080.md ruled out 2 %
  // and a 31x31 box; 5 % (a held-out shot's) and 10 % chose alike there.
  int driftBox = 31;
  double driftThreshold = 0.05;
  // The noisy renders themselves, averaged over (2 lightBox + 1)^2 pixels,
  // must agree within their standard error: the weight falls from 1 at
  // lightLow standard errors to 0 at lightHigh (a change of light).
  int lightBox = 5;
  double lightLow = 2.0;
  double lightHigh = 4.0;
  // Noise residuals correlated above this with the frame's: the neighbour
  // repeats the frame's noise (a fixed seed on a still camera) and adds nothing.
  double repeatedNoiseCorrelation = 0.5;
  // The share of the accumulated render, denoised, in the result
  // (blendWithHistory); 0: the filtered results alone, one network pass a
  // frame. Chosen on the tuning half of experiments/shots/SPLIT.md (its
  // denoising the default-size network on the prefilter's aux): 0.3 to 0.4
  // within 0.02 dB at 4 and 16 spp, 0.5 0.04-0.07 dB less, 0.6 0.1-0.16 less.
  double accumulatedShare = 0.35;
  // A light pass's share where its render gathered nothing, rising to
  // accumulatedShare at two frames: there its history is only a smaller
  // network's second opinion of the same render. The view-dependent passes
  // (glossy, transmission; where they moved on screen) gain from it; at 15 % a
  // turning metal bottle's residual, at 25 % its Glossy Direct, fell below
  // the pass alone. The others (diffuse) gain on some shots and lose on
  // others: at 35 % two rolling balls' Diffuse Direct and Indirect lost 0.3 dB
  // to the passes alone. Chosen on the tuning side of
  // experiments/shots/SPLIT_1080.md.
  double viewDependentShareAlone = 0.2;
  double lightShareAlone = 0.0;
  // viewDependentShareAlone is taken in full where the view-dependent passes
  // hold at least this share of the frame's light (WindowFrame::viewDependent),
  // in proportion below it: on matte surfaces, where their light is faint, the
  // smaller network's opinion is the worse one. On the tuning side of
  // experiments/shots/SPLIT_1080.md three shots whose faint Glossy Indirect
  // fell 0.04 to 0.06 dB below the pass alone came to -0.006 to +0.012 at 1
  // (-0.012 to +0.010 at 0.5), a glossy toy car kept +0.11 of its +0.12, and
  // a turning bottle's glossy passes rose from -0.01 to +0.02 and more.
  // 0: in full everywhere.
  double viewDependentShareFull = 1.0;
  // Where a neighbour's light drifted (driftThreshold), the light is changing
  // between the frames: a light pass that is not view-dependent then takes
  // that neighbour only where its own renders also pass a light test, with
  // the weight falling from 1 at passLightLow standard errors to 0 at
  // passLightHigh (passLightTested). The colour's test sees the sum of the
  // passes, and a change in one of them (a turning chair's direct light)
  // hides there under the others' noise. On the tuning side of
  // experiments/shots/SPLIT_1080.md: chair_turn's Diffuse Direct went from
  // 0.12 dB below the pass alone to 0.62 above (0.82 at the colour's 2 and
  // 4, which cost up to 0.05 dB where the camera moved and the light did
  // not; testing every neighbour cost up to 0.1 dB there). 0: off.
  double passLightLow = 3.0;
  double passLightHigh = 6.0;
  // The past frames' denoised histories count where the surface stood still
  // on screen, fully, falling to nothing at this many pixels of motion. Where
  // it moved, each was resampled on its way in and its errors follow the
  // filtered results' (the tuning half lost 0.1-0.2 dB at 16 spp without it).
  double historyMotion = 0.5;
  // A reflection on a turning bottle, a highlight as the camera dollies:
  // light that moves with the view arrives misplaced from a neighbour whose
  // surface moved on screen, however well the surface is brought in, and no
  // per-pixel test at the render's noise tells it from the leftover errors.
  // Where the frame knows its view-dependent share, that share of each
  // neighbour's weight falls linearly to nothing at this many pixels of
  // motion (0: off).
  double viewDependentMotion = 0.5;
  int threads = 1;  // neighbours brought in at once; the result does not depend on it
  // Where set, each neighbour's weight per pixel after the tests above is
  // multiplied by this network's: it takes trust away where they pass what
  // does not follow the motion.
  std::shared_ptr<const LearnedTrust> learnedTrust;
  // Where set, called once a frame with its neighbours' features and weights.
  std::function<void(const TrustSamples&)> observeTrust;
};

// What one frame took from its neighbours, for -v.
struct TemporalStats {
  double historyShare = 0.0;       // mean over pixels of the neighbours' share of the weight
  int neighbours = 0;              // neighbours available in the window
  int repeatedNoise = 0;           // of them, rejected for repeating the frame's noise
  int relit = 0;                   // of them, brought to the frame's light first
  int drifted = 0;                 // of them, brought to it where its light drifted
  int changedLight = 0;            // of them, rejected for a change of light over the frame
  std::vector<double> trusted;     // per neighbour: share of pixels it contributed to
  double accumulatedFrames = 1.0;  // mean over pixels of the frames in the accumulated render
};

// The past neighbours' denoised histories, brought into the frame, for
// historyMean; empty where no neighbour carries one.
struct PastHistories {
  std::vector<Image> images;
  // Per image and pixel: its result's weight where the surface stood still.
  std::vector<std::vector<double>> weights;
  std::vector<std::size_t> frames;  // per image: its frame's index in the window
  double scale = 1.0;               // the frame's autoexposure, and
  std::vector<float> noise;         // its render's local noise level: the light test's scale
  bool empty() const { return images.empty(); }
};

// What filterFrame did with one neighbour, so that any other image of the
// window's frames (a light pass denoised alone) is filtered as the colour
// was, without the tests: the same taps, the same per-pixel weights.
struct NeighbourWeights {
  std::size_t frame = 0;          // its index in the window
  motion::Resampling resampling;  // how its images are brought into the frame
  // Brought to the frame's light first (a lamp moved): each image by its own
  // factor, the ratio of its box means over the trusted pixels.
  bool relit = false;
  // Per pixel, 1 where the colour was brought to it for a light that drifted
  // (TemporalOptions::driftThreshold): there each image by its own wide
  // boxes' ratio. Empty: nowhere.
  std::vector<unsigned char> drifted;
  std::vector<double> weight;  // per pixel, after every test; the frame's own weighs 1
};

struct FilterWeights {
  std::size_t centre = 0;
  int relightBox = 1;
  double relightRange = 10.0;
  int driftBox = 31;
  std::vector<NeighbourWeights> neighbours;  // those it used, in the order of its sums
  bool empty() const { return neighbours.empty(); }
};

struct TemporalResult {
  Image color;            // the filtered results
  FilterWeights weights;  // how they were filtered
  // The noisy renders accumulated with the same weights, and per pixel the
  // effective number of frames in it; empty where accumulatedShare is 0.
  Image history;
  Image historyFrames;
  PastHistories pastHistories;
  TemporalStats stats;
};

// The result for window[centre]: `window` holds consecutive frames (nullptr
// where a frame is missing, which ends the chain on that side), window[centre]
// the frame itself. Deterministic: depends only on the frames given.
TemporalResult filterFrame(const std::vector<const WindowFrame*>& window, std::size_t centre,
                           const TemporalOptions& options = {});

// `images[k]` (window frame k's image of any channel count, nullptr where it
// has none, and that neighbour is then left out) filtered over the window by
// `weights`: the centre's image weighs 1, each neighbour's brought in and
// weighed as filterFrame did. With the frames' denoised results it gives
// TemporalResult::color bit for bit (Catmull-Rom falls back to bilinear where
// an image's own values would overshoot below 0, so with the past's histories
// stacked in, a pixel where theirs did may differ). Throws
// std::invalid_argument when the centre's image is missing.
// `stillPixels` above 0: each neighbour's weight also falls linearly to 0 at
// that much motion on screen, for an image of light that moves with the view,
// not the surface (TemporalOptions::viewDependentMotion).
// `tested`, where given: per neighbour of `weights`, its weights per pixel in
// place of its own (passLightTested's; where it has none or an empty one: its own).
using TestedWeights = std::vector<std::vector<double>>;
Image filterWith(const FilterWeights& weights, const std::vector<const Image*>& images,
                 double stillPixels = 0.0, const TestedWeights* tested = nullptr);

// `renders` (each window frame's render of any image, nullptr where none)
// accumulated as the colour's renders were (TemporalResult::history): each
// neighbour's brought in at the nearest pixel and weighed as filterWith
// weighs it, a relit one by the factor of its `results` image (the same
// image denoised), stillPixels as there. With the frames' renders and results
// it gives TemporalResult::history bit for bit; `frames`, where given, gets
// its effective number of frames per pixel, as TemporalResult::historyFrames. Throws
// std::invalid_argument when the centre's render or result is missing.
Image accumulateWith(const FilterWeights& weights, const std::vector<const Image*>& renders,
                     const std::vector<const Image*>& results, double stillPixels = 0.0,
                     Image* frames = nullptr, const TestedWeights* tested = nullptr);

// The frame's accumulated render, denoised (`own`), averaged with its past
// neighbours' as its result was with theirs where the surface stood still,
// less where one differs from `own` by more than the noise of its
// accumulated render explains (a light that moved since); own where none
// carries one.
Image historyMean(const Image& own, const TemporalResult& result,
                  const TemporalOptions& options = {});

// The weights historyMean gives the past histories, as FilterWeights over the
// window (the frame's own weighs 1), so that any other image's histories (a
// light pass's accumulated render, denoised) are averaged as the colour's:
// filterWith with them (a relit or drifted neighbour's history is then
// brought to the frame's light by its own factor, the colour's by its
// result's). `taps`: result.weights, or FilterWeights that still hold the
// past neighbours wanted; those it lacks are left out. Empty where no past
// neighbour carries a history.
FilterWeights historyWeights(const Image& own, const TemporalResult& result,
                             const FilterWeights& taps, const TemporalOptions& options = {});

// `taps`' neighbours of window frames `frames`, in that order, each with the
// weights given for it instead.
FilterWeights pastWeights(const FilterWeights& taps, const std::vector<std::size_t>& frames,
                          std::vector<std::vector<double>> weights);

// (1 - share) filtered + share accumulated, per pixel: `accumulated` is
// TemporalResult::history denoised (and averaged by historyMean). Where no
// neighbour was trusted the history is the frame's own render, so both are
// the frame denoised alone.
Image blendWithHistory(const Image& filtered, const Image& accumulated, double share);
// A light pass's share of its history per pixel, from the effective frames
// its render accumulated (accumulateWith's `frames`): `alone` (at most
// TemporalOptions::accumulatedShare; viewDependentShareAlone or
// lightShareAlone) at one frame, rising linearly to accumulatedShare at two.
Image passHistoryShare(const Image& frames, double alone, const TemporalOptions& options);
// The same with `alone` per pixel (one channel, `frames`' size).
Image passHistoryShare(const Image& frames, const Image& alone, const TemporalOptions& options);
// A view-dependent pass's share alone per pixel (TemporalOptions::
// viewDependentShareAlone, viewDependentShareFull), from its frame's
// WindowFrame::viewDependent.
Image viewDependentAlone(const Image& viewDependent, const TemporalOptions& options);
// For each neighbour of `weights` whose light drifted, its weights times the
// renders' light test (TemporalOptions::lightBox, passLightLow,
// passLightHigh) on one light pass's own `renders`, brought to the
// frame's light as filterWith brings them, their noise read against its
// `results` (each frame's pass denoised alone); the other neighbours' empty.
// Empty where no neighbour drifted, passLightHigh is 0 or the centre's
// images are missing.
TestedWeights passLightTested(const FilterWeights& weights,
                              const std::vector<const Image*>& renders,
                              const std::vector<const Image*>& results,
                              const TemporalOptions& options);
// blendWithHistory with a share per pixel (a one-channel image).
Image blendWithHistory(const Image& filtered, const Image& accumulated, const Image& share);

}  // namespace dn::temporal
