// Training data: finds a data set's frames (docs/dataset.md) and turns them into
// batches of (noisy colour, auxiliary buffers, target) crops. Plain C++: the
// trainer wraps the planar float arrays as tensors without copying.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "dn/image.h"
#include "dn/io/buffers.h"

namespace dn::data {

// One rendered frame: DIR/<split>/scene_<seed>/frame_<k>/ with meta.json written last.
struct FrameRecord {
  std::string dir;
  std::string split;
  int stacks = 0;    // independent low-spp renders, spp<stackSpp>_00.exr ...
  int stackSpp = 0;  // samples per pixel of each stack
};

// Complete frames (meta.json present) of one split ("" for all), sorted by path.
// Throws IoError naming the folder when it has no frames.
std::vector<FrameRecord> scanDataset(const std::string& root, const std::string& split = "");

enum class Task {
  Denoise,  // low-spp average + its aux buffers -> clean target (gt_clean, else mean of gt_a/gt_b)
  Cleanse,  // one ground truth + its aux buffers -> the other ground truth (swapped at random)
  Clean,    // the clean target alone (as both color and target): pretraining images
};

struct SampleOptions {
  Task task = Task::Denoise;
  std::vector<int> spp = {4, 16, 64};  // input sample counts drawn uniformly
  std::vector<std::string> aux;        // canonical buffer names, concatenated in this order
  int crop = 64;                       // square crop size; 0 keeps the whole frame
  bool augment = true;                 // random flips and 90-degree rotations
  // Aux buffers a frame lacks are zero (Sample::present says which) instead of
  // an error: renderers write different passes.
  bool missingAuxAsZero = false;
};

// Dihedral transform of an image: transpose, then horizontal and vertical flips.
struct Orientation {
  bool transpose = false, flipX = false, flipY = false;
};

// Applies an orientation to an image. Channels [normalChannel, normalChannel + 3)
// hold camera-space normals (x right, y up, as Cycles writes Denoising Normal):
// those vectors are turned with the image. -1: no normals.
Image orient(const Image& image, Orientation o, int normalChannel = -1);

// Mean of several images of the same shape.
Image average(const std::vector<const Image*>& images);

struct Sample {
  Image color;   // linear HDR, 3 channels
  Image aux;     // the aux buffers concatenated (may have 0 channels)
  Image target;  // linear HDR, 3 channels
  int spp = 0;
  std::vector<float> present;  // per aux buffer: 1 in the frame's files, 0 filled with zeros
};

// An image stored as IEEE half floats: half the memory of Image. The cache keeps
// the noisy stacks this way (their noise dwarfs half's 11-bit precision), so
// twice as many frames fit; targets stay float.
struct HalfImage {
  int width = 0, height = 0, channels = 0;
  std::vector<std::uint16_t> bits;  // interleaved like Image::pixels

  static HalfImage from(const Image& image);  // magnitudes above 65504 clamp to it
  Image toImage() const;
};

// All buffers of one frame that samples need, decoded once and cached.
class FrameData {
 public:
  static std::shared_ptr<const FrameData> load(const FrameRecord& record,
                                               const SampleOptions& options);
  // A sample with everything random drawn from rng: spp, stacks, crop, orientation.
  Sample draw(std::mt19937_64& rng, const SampleOptions& options) const;
  std::size_t bytes() const;
  int width() const { return width_; }
  int height() const { return height_; }

 private:
  int width_ = 0, height_ = 0, stackSpp_ = 0;
  std::vector<float> present_;
  std::vector<HalfImage> stackColor_, stackAux_;  // per stack
  Image gtAColor_, gtAAux_, gtBColor_, gtBAux_, target_;
};

// Planar (N, C, H, W) float batches.
struct Batch {
  int size = 0, height = 0, width = 0, auxChannels = 0;
  std::vector<float> color, aux, target;
  std::vector<int> spp;
  std::vector<float> present;  // (N, aux buffers): Sample::present of each sample
};

struct LoaderOptions {
  int batchSize = 8;
  int threads = 2;          // background workers that decode and crop
  int queueDepth = 32;      // samples prepared ahead of the consumer
  int samplesPerVisit = 4;  // consecutive samples drawn from one frame visit
  std::uint64_t seed = 1;
  std::size_t cacheBytes = std::size_t(4) << 30;  // decoded frames kept in memory
};

// Deterministic stream of batches: sample i depends only on (seed, i), so a
// resumed run that seeks to its position sees exactly the same data.
class Loader {
 public:
  Loader(std::vector<FrameRecord> frames, SampleOptions sampleOptions, LoaderOptions options,
         std::uint64_t startSample = 0);
  ~Loader();
  Loader(const Loader&) = delete;
  Loader& operator=(const Loader&) = delete;

  Batch next();
  std::uint64_t position() const { return nextToDeliver_; }  // samples delivered so far

 private:
  void work();
  Sample makeSample(std::uint64_t index);
  std::shared_ptr<const FrameData> frame(std::size_t index);

  std::vector<FrameRecord> frames_;
  SampleOptions sampleOptions_;
  LoaderOptions options_;

  std::mutex mutex_;
  std::condition_variable ready_, space_;
  std::map<std::uint64_t, Sample> done_;
  std::string error_;  // first worker error, rethrown by next()
  std::uint64_t nextToClaim_, nextToDeliver_;
  bool stop_ = false;

  std::mutex cacheMutex_;
  std::list<std::pair<std::size_t, std::shared_ptr<const FrameData>>> cache_;  // most recent first
  std::size_t cachedBytes_ = 0;

  std::vector<std::thread> workers_;
};

}  // namespace dn::data
