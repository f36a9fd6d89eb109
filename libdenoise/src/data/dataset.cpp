#include "dn/data/dataset.h"

#include <algorithm>
#include <filesystem>
#include <numeric>
#include <regex>

#include <Imath/half.h>

#include "dn/io/buffer_io.h"

namespace dn::data {

namespace fs = std::filesystem;

namespace {

std::vector<fs::path> sortedSubdirs(const fs::path& dir, const std::string& prefix) {
  std::vector<fs::path> out;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.is_directory() && e.path().filename().string().rfind(prefix, 0) == 0)
      out.push_back(e.path());
  std::sort(out.begin(), out.end());
  return out;
}

// The low-spp stacks of a frame folder: spp<N>_<k>.exr.
void countStacks(const fs::path& dir, FrameRecord& record) {
  static const std::regex pattern(R"(spp(\d+)_(\d+)\.exr)");
  for (const auto& e : fs::directory_iterator(dir)) {
    std::smatch m;
    std::string name = e.path().filename().string();
    if (!std::regex_match(name, m, pattern)) continue;
    record.stackSpp = std::stoi(m[1]);
    ++record.stacks;
  }
}

std::string stackPath(const std::string& dir, int spp, int k) {
  char name[32];
  std::snprintf(name, sizeof name, "spp%d_%02d.exr", spp, k);
  return (fs::path(dir) / name).string();
}

// Colour plus the requested aux buffers of one file, aux concatenated; with
// `present`, missing aux buffers are zeros and flagged 0 there.
std::pair<Image, Image> readColorAndAux(const std::string& path,
                                        const std::vector<std::string>& aux,
                                        std::vector<float>* present = nullptr) {
  ReadOptions options;
  options.only = aux;
  if (present) {  // only what the file has: readFrame refuses the rest
    const auto has = availableBuffers(path);
    options.only.clear();
    for (const auto& name : aux)
      if (std::find(has.begin(), has.end(), name) != has.end()) options.only.push_back(name);
  }
  options.only.insert(options.only.begin(), "color");
  FrameBuffers frame = readFrame(path, options);
  int channels = 0;
  for (const auto& name : aux) channels += findBufferSpec(name)->channels;
  Image auxImage(frame.width, frame.height, channels);
  if (present) present->clear();
  int offset = 0;
  for (const auto& name : aux) {
    const int c = findBufferSpec(name)->channels;
    const bool has = frame.has(name);
    if (present) present->push_back(has ? 1.0f : 0.0f);
    if (has) {
      const Image& b = frame.get(name);
      for (std::size_t i = 0; i < b.pixelCount(); ++i)
        for (int k = 0; k < c; ++k)
          auxImage.pixels[i * channels + offset + k] =
              b.pixels[i * b.channels + std::min(k, b.channels - 1)];
    } else if (!present) {
      frame.get(name);  // throws, naming the buffer
    }
    offset += c;
  }
  return {frame.get("color"), std::move(auxImage)};
}

Image crop(const Image& image, int x0, int y0, int w, int h) {
  Image out(w, h, image.channels);
  for (int y = 0; y < h; ++y)
    std::copy_n(image.pixel(x0, y0 + y), static_cast<std::size_t>(w) * image.channels,
                out.pixel(0, y));
  return out;
}

float toFloat(float v) { return v; }
float toFloat(std::uint16_t bits) { return imath_half_to_float(bits); }

const float* pixelData(const Image& image, int x, int y) { return image.pixel(x, y); }
const std::uint16_t* pixelData(const HalfImage& image, int x, int y) {
  return image.bits.data() + (static_cast<std::size_t>(y) * image.width + x) * image.channels;
}

// Mean of the same crop of several images (Image or HalfImage).
template <class Source>
Image cropAverage(const std::vector<const Source*>& images, int x0, int y0, int w, int h) {
  Image out(w, h, images.front()->channels);
  const float scale = 1.0f / images.size();
  const std::size_t rowValues = static_cast<std::size_t>(w) * out.channels;
  for (const Source* img : images)
    for (int y = 0; y < h; ++y) {
      const auto* src = pixelData(*img, x0, y0 + y);
      float* dst = out.pixel(0, y);
      for (std::size_t i = 0; i < rowValues; ++i) dst[i] += toFloat(src[i]) * scale;
    }
  return out;
}

int normalOffset(const std::vector<std::string>& aux) {
  int offset = 0;
  for (const auto& name : aux) {
    if (name == "normal") return offset;
    offset += findBufferSpec(name)->channels;
  }
  return -1;
}

std::uint64_t splitmix(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

}  // namespace

std::vector<FrameRecord> scanDataset(const std::string& root, const std::string& split) {
  if (!fs::is_directory(root)) throw IoError(root + ": no such data set folder");
  std::vector<fs::path> splits;
  if (!split.empty())
    splits.push_back(fs::path(root) / split);
  else
    splits = sortedSubdirs(root, "");
  std::vector<FrameRecord> frames;
  for (const auto& splitDir : splits)
    for (const auto& scene : sortedSubdirs(splitDir, "scene_"))
      for (const auto& frameDir : sortedSubdirs(scene, "frame_")) {
        if (!fs::exists(frameDir / "meta.json")) continue;  // unfinished
        FrameRecord record{frameDir.string(), splitDir.filename().string(), 0, 0};
        countStacks(frameDir, record);
        frames.push_back(record);
      }
  if (frames.empty())
    throw IoError(root + ": no finished frames" +
                  (split.empty() ? "" : " in split '" + split + "'"));
  return frames;
}

Image orient(const Image& image, Orientation o, int normalChannel) {
  const int w = o.transpose ? image.height : image.width;
  const int h = o.transpose ? image.width : image.height;
  Image out(w, h, image.channels);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      int sx = o.flipX ? w - 1 - x : x, sy = o.flipY ? h - 1 - y : y;
      if (o.transpose) std::swap(sx, sy);
      std::copy_n(image.pixel(sx, sy), image.channels, out.pixel(x, y));
      if (normalChannel < 0) continue;
      float* n = out.pixel(x, y) + normalChannel;
      // Image rows run down while camera y runs up: a transpose maps (x, y) to (-y, -x).
      if (o.transpose) std::tie(n[0], n[1]) = std::make_pair(-n[1], -n[0]);
      if (o.flipX) n[0] = -n[0];
      if (o.flipY) n[1] = -n[1];
    }
  return out;
}

HalfImage HalfImage::from(const Image& image) {
  constexpr float kHalfMax = 65504.0f;
  HalfImage out{image.width, image.height, image.channels, {}};
  out.bits.resize(image.pixels.size());
  for (std::size_t i = 0; i < image.pixels.size(); ++i)
    out.bits[i] = imath_float_to_half(std::clamp(image.pixels[i], -kHalfMax, kHalfMax));
  return out;
}

Image HalfImage::toImage() const {
  Image out(width, height, channels);
  for (std::size_t i = 0; i < bits.size(); ++i) out.pixels[i] = toFloat(bits[i]);
  return out;
}

Image average(const std::vector<const Image*>& images) {
  return cropAverage(images, 0, 0, images.front()->width, images.front()->height);
}

std::shared_ptr<const FrameData> FrameData::load(const FrameRecord& record,
                                                 const SampleOptions& options) {
  auto data = std::make_shared<FrameData>();
  const fs::path dir(record.dir);
  auto loadTarget = [&] {
    if (fs::exists(dir / "gt_clean.exr")) return readImage((dir / "gt_clean.exr").string(), 3);
    Image a = readImage((dir / "gt_a.exr").string(), 3),
          b = readImage((dir / "gt_b.exr").string(), 3);
    return average({&a, &b});
  };
  if (options.task == Task::Clean) {
    data->target_ = loadTarget();
    data->width_ = data->target_.width;
    data->height_ = data->target_.height;
  } else if (options.task == Task::Denoise) {
    int maxSpp = *std::max_element(options.spp.begin(), options.spp.end());
    if (record.stackSpp <= 0 || maxSpp > record.stacks * record.stackSpp)
      throw IoError(record.dir + ": " + std::to_string(maxSpp) + " spp needs " +
                    std::to_string(maxSpp / std::max(record.stackSpp, 1)) + " stacks of " +
                    std::to_string(record.stackSpp) + " spp, the frame has " +
                    std::to_string(record.stacks));
    for (int k = 0; k < record.stacks; ++k) {
      auto [color, aux] = readColorAndAux(stackPath(record.dir, record.stackSpp, k), options.aux,
                                          options.missingAuxAsZero ? &data->present_ : nullptr);
      data->stackColor_.push_back(HalfImage::from(color));
      data->stackAux_.push_back(HalfImage::from(aux));
    }
    data->stackSpp_ = record.stackSpp;
    data->target_ = loadTarget();
    data->width_ = data->target_.width;
    data->height_ = data->target_.height;
  } else {
    std::tie(data->gtAColor_, data->gtAAux_) =
        readColorAndAux((dir / "gt_a.exr").string(), options.aux);
    std::tie(data->gtBColor_, data->gtBAux_) =
        readColorAndAux((dir / "gt_b.exr").string(), options.aux);
    data->width_ = data->gtAColor_.width;
    data->height_ = data->gtAColor_.height;
  }
  if (options.crop > data->width_ || options.crop > data->height_)
    throw IoError(record.dir + ": frame is " + std::to_string(data->width_) + "x" +
                  std::to_string(data->height_) + ", smaller than the crop " +
                  std::to_string(options.crop));
  return data;
}

Sample FrameData::draw(std::mt19937_64& rng, const SampleOptions& options) const {
  auto uniform = [&](int n) {
    return static_cast<int>(std::uniform_int_distribution<int>(0, n - 1)(rng));
  };
  const int w = options.crop > 0 ? options.crop : width_,
            h = options.crop > 0 ? options.crop : height_;
  const int x0 = uniform(width_ - w + 1), y0 = uniform(height_ - h + 1);

  Sample s;
  s.present = present_;
  if (options.task == Task::Clean) {
    s.target = crop(target_, x0, y0, w, h);
    s.color = s.target;
    s.aux = Image(w, h, 0);
  } else if (options.task == Task::Denoise) {
    s.spp = options.spp[uniform(static_cast<int>(options.spp.size()))];
    std::vector<int> order(stackColor_.size());
    std::iota(order.begin(), order.end(), 0);
    std::shuffle(order.begin(), order.end(), rng);
    order.resize(s.spp / stackSpp_);
    std::vector<const HalfImage*> colors, auxes;
    for (int k : order) colors.push_back(&stackColor_[k]), auxes.push_back(&stackAux_[k]);
    s.color = cropAverage(colors, x0, y0, w, h);
    s.aux = cropAverage(auxes, x0, y0, w, h);
    s.target = crop(target_, x0, y0, w, h);
  } else {
    bool swap = uniform(2) == 1;  // Noise2Noise: either render predicts the other
    s.color = crop(swap ? gtBColor_ : gtAColor_, x0, y0, w, h);
    s.aux = crop(swap ? gtBAux_ : gtAAux_, x0, y0, w, h);
    s.target = crop(swap ? gtAColor_ : gtBColor_, x0, y0, w, h);
  }
  if (options.augment) {
    Orientation o{uniform(2) == 1, uniform(2) == 1, uniform(2) == 1};
    s.color = orient(s.color, o);
    s.aux = orient(s.aux, o, normalOffset(options.aux));
    s.target = orient(s.target, o);
  }
  return s;
}

std::size_t FrameData::bytes() const {
  const std::size_t floats =
      target_.size() + gtAColor_.size() + gtAAux_.size() + gtBColor_.size() + gtBAux_.size();
  std::size_t halves = 0;
  for (std::size_t k = 0; k < stackColor_.size(); ++k)
    halves += stackColor_[k].bits.size() + stackAux_[k].bits.size();
  return floats * sizeof(float) + halves * sizeof(std::uint16_t);
}

Loader::Loader(std::vector<FrameRecord> frames, SampleOptions sampleOptions, LoaderOptions options,
               std::uint64_t startSample)
    : frames_(std::move(frames)),
      sampleOptions_(std::move(sampleOptions)),
      options_(options),
      nextToClaim_(startSample),
      nextToDeliver_(startSample) {
  if (frames_.empty()) throw IoError("(data set): no frames to load");
  for (const auto& name : sampleOptions_.aux)
    if (!findBufferSpec(name)) throw std::invalid_argument("unknown aux buffer '" + name + "'");
  for (int t = 0; t < std::max(1, options_.threads); ++t) workers_.emplace_back([this] { work(); });
}

Loader::~Loader() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  space_.notify_all();
  for (auto& w : workers_) w.join();
}

std::shared_ptr<const FrameData> Loader::frame(std::size_t index) {
  {
    std::lock_guard<std::mutex> lock(cacheMutex_);
    for (auto it = cache_.begin(); it != cache_.end(); ++it)
      if (it->first == index) {
        cache_.splice(cache_.begin(), cache_, it);
        return it->second;
      }
  }
  auto data = FrameData::load(frames_[index], sampleOptions_);
  std::lock_guard<std::mutex> lock(cacheMutex_);
  cache_.emplace_front(index, data);
  cachedBytes_ += data->bytes();
  while (cachedBytes_ > options_.cacheBytes && cache_.size() > 1) {
    cachedBytes_ -= cache_.back().second->bytes();
    cache_.pop_back();
  }
  return data;
}

Sample Loader::makeSample(std::uint64_t index) {
  // Frames are visited in a fresh permutation every epoch; each visit yields a few samples.
  const std::uint64_t visit = index / std::max(1, options_.samplesPerVisit);
  const std::uint64_t epoch = visit / frames_.size();
  std::vector<std::size_t> order(frames_.size());
  std::iota(order.begin(), order.end(), 0);
  std::mt19937_64 epochRng(splitmix(options_.seed ^ splitmix(epoch + 1)));
  std::shuffle(order.begin(), order.end(), epochRng);
  std::mt19937_64 rng(splitmix(options_.seed + splitmix(index)));
  return frame(order[visit % frames_.size()])->draw(rng, sampleOptions_);
}

void Loader::work() {
  for (;;) {
    std::uint64_t index;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      space_.wait(lock, [&] {
        return stop_ ||
               nextToClaim_ < nextToDeliver_ + static_cast<std::uint64_t>(options_.queueDepth);
      });
      if (stop_) return;
      index = nextToClaim_++;
    }
    Sample sample;
    std::string error;
    try {
      sample = makeSample(index);
    } catch (const std::exception& e) {
      error = e.what();
    }
    std::lock_guard<std::mutex> lock(mutex_);
    if (!error.empty() && error_.empty()) error_ = error;
    done_.emplace(index, std::move(sample));
    ready_.notify_all();
  }
}

Batch Loader::next() {
  Batch batch;
  batch.size = options_.batchSize;
  for (int b = 0; b < options_.batchSize; ++b) {
    Sample s;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      ready_.wait(lock, [&] { return !error_.empty() || done_.count(nextToDeliver_); });
      if (!error_.empty()) throw IoError(error_);
      auto it = done_.find(nextToDeliver_);
      s = std::move(it->second);
      done_.erase(it);
      ++nextToDeliver_;
    }
    space_.notify_all();
    if (b == 0) {
      batch.height = s.color.height;
      batch.width = s.color.width;
      batch.auxChannels = s.aux.channels;
      const std::size_t plane = static_cast<std::size_t>(batch.height) * batch.width;
      batch.color.resize(batch.size * 3 * plane);
      batch.target.resize(batch.size * 3 * plane);
      batch.aux.resize(batch.size * batch.auxChannels * plane);
    } else if (s.color.width != batch.width || s.color.height != batch.height) {
      throw std::invalid_argument("frames of different sizes in one batch: set a crop size");
    }
    const std::size_t plane = static_cast<std::size_t>(batch.height) * batch.width;
    auto toPlanar = [&](const Image& img, std::vector<float>& dst) {
      float* base = dst.data() + static_cast<std::size_t>(b) * img.channels * plane;
      for (std::size_t i = 0; i < plane; ++i)
        for (int c = 0; c < img.channels; ++c)
          base[c * plane + i] = img.pixels[i * img.channels + c];
    };
    toPlanar(s.color, batch.color);
    toPlanar(s.aux, batch.aux);
    toPlanar(s.target, batch.target);
    batch.spp.push_back(s.spp);
    batch.present.insert(batch.present.end(), s.present.begin(), s.present.end());
  }
  return batch;
}

}  // namespace dn::data
