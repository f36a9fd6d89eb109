// The temporal default's cost per frame against frame-by-frame denoising, on
// a synthetic shot made from one frame of .npy buffers (as denoise_npy_bench
// reads them), without OpenImageIO: for the GPU machine (bench/gpu/check_cuda.sh).
//
//   temporal_npy_bench --input DIR [--model models/default.dnm] [--device cpu|cuda]
//       [--precision float|bf16|fp16] [--radius 4] [--frames 3] [--motion 3,2]
//
// Frame k is the input moved by k times the motion (wrapping at the edges),
// its motion vectors that constant motion. Its noise must not move with the
// scene, or the filter would take every neighbour for a repeat of the frame's
// own noise: the colour is the input denoised alone (a stand-in for the clean
// image) moved with the scene, plus the input's residual noise moved
// elsewhere, clamped at 0.
//
// Each frame runs what dn::temporal::Sequence::denoise runs for it once the
// shot is under way (Sequence itself reads files, so it needs OpenImageIO):
// the frame entering the window denoised alone, the filter over the window
// (dn::temporal::filterFrame), the accumulated render denoised on the
// prefilter's clean aux, its mean with the past frames' and the blend. The
// networks run on the device, the filter on the CPU. Frames are timed once
// `radius` frames have their histories (the steady state); making the
// synthetic frames is not timed. Lines "RESULT key=value ..." are for scripts.
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "dn/infer/denoiser.h"
#include "dn/infer/device.h"
#include "dn/io/npy.h"
#include "dn/temporal/temporal_filter.h"

namespace {

struct Args {
  std::string input, model = "models/default.dnm", device = "cpu";
  dn::Precision precision = dn::Precision::Float;
  int radius = dn::temporal::TemporalOptions().radius;
  int frames = 3;
  int dx = 3, dy = 2;  // pixels a frame
};

struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

int integer(const std::string& flag, const std::string& value, int least, int most) {
  try {
    std::size_t used = 0;
    const int n = std::stoi(value, &used);
    if (used == value.size() && n >= least && n <= most) return n;
  } catch (const std::exception&) {
  }
  throw UsageError(flag + " needs an integer from " + std::to_string(least) + " to " +
                   std::to_string(most) + ", got '" + value + "'");
}

Args parseArgs(int argc, char** argv) {
  Args args;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "-h" || flag == "--help") throw UsageError("");
    if (i + 1 >= argc) throw UsageError(flag + " needs a value (or is unknown)");
    const std::string value = argv[++i];
    if (flag == "--input") {
      args.input = value;
    } else if (flag == "--model") {
      args.model = value;
    } else if (flag == "--device") {
      args.device = value;
    } else if (flag == "--precision" && dn::precisionFromName(value)) {
      args.precision = *dn::precisionFromName(value);
    } else if (flag == "--radius") {
      args.radius = integer(flag, value, 1, 8);
    } else if (flag == "--frames") {
      args.frames = integer(flag, value, 1, 100);
    } else if (flag == "--motion") {
      const std::size_t comma = value.find(',');
      if (comma == std::string::npos) throw UsageError("--motion needs DX,DY, got '" + value + "'");
      args.dx = integer(flag, value.substr(0, comma), -64, 64);
      args.dy = integer(flag, value.substr(comma + 1), -64, 64);
    } else {
      throw UsageError("unknown argument " + flag + " " + value);
    }
  }
  if (args.input.empty()) throw UsageError("--input DIR is required");
  return args;
}

// new(x, y) = old(x - sx, y - sy), wrapping at the edges.
dn::Image moved(const dn::Image& image, int sx, int sy) {
  dn::Image out(image.width, image.height, image.channels);
  const int w = image.width, h = image.height;
  for (int y = 0; y < h; ++y) {
    const int from = ((y - sy) % h + h) % h;
    for (int x = 0; x < w; ++x) {
      const float* p = image.pixel(((x - sx) % w + w) % w, from);
      std::copy(p, p + image.channels,
                out.pixels.begin() + (std::size_t(y) * w + x) * image.channels);
    }
  }
  return out;
}

dn::Image constant(int width, int height, float a, float b) {
  dn::Image out(width, height, 2);
  for (std::size_t i = 0; i < out.pixels.size(); i += 2) out.pixels[i] = a, out.pixels[i + 1] = b;
  return out;
}

// The synthetic shot (see the top of the file).
class Shot {
 public:
  Shot(dn::FrameBuffers base, const dn::Image& clean, const Args& args)
      : base_(std::move(base)), clean_(clean), residual_(base_.get("color")), args_(args) {
    for (std::size_t i = 0; i < residual_.pixels.size(); ++i)
      residual_.pixels[i] -= clean.pixels[i];
  }

  dn::FrameBuffers frame(int k) const {
    dn::FrameBuffers out = base_;
    const int sx = k * args_.dx, sy = k * args_.dy;
    for (auto& [name, image] : out.buffers)
      if (name != "color") image = moved(image, sx, sy);
    // The noise moves 37 and 23 pixels a frame less than the scene.
    dn::Image color = moved(clean_, sx, sy);
    const dn::Image noise = moved(residual_, sx - 37 * k, sy - 23 * k);
    for (std::size_t i = 0; i < color.pixels.size(); ++i)
      color.pixels[i] = std::max(0.0f, color.pixels[i] + noise.pixels[i]);
    out.buffers["color"] = std::move(color);
    return out;
  }

  dn::motion::MotionField motion() const {
    dn::motion::MotionField field;
    field.toPrevious = constant(base_.width, base_.height, -float(args_.dx), -float(args_.dy));
    field.toNext = constant(base_.width, base_.height, float(args_.dx), float(args_.dy));
    field.source = "synthetic constant motion";
    return field;
  }

 private:
  dn::FrameBuffers base_;
  dn::Image clean_, residual_;
  Args args_;
};

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

double median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

// A frame of the window, as Sequence keeps it.
struct Held {
  dn::FrameBuffers buffers;  // for its history's denoising
  dn::temporal::WindowFrame frame;
  dn::Image cleanAlbedo, cleanNormal;
};

// The frame with its colour replaced by the accumulated render, on the
// prefilter's clean aux (Sequence's withHistory).
dn::FrameBuffers withHistory(const Held& held, dn::Image history) {
  dn::FrameBuffers out = held.buffers;
  out.buffers["color"] = std::move(history);
  if (!held.cleanAlbedo.empty() && !held.cleanNormal.empty()) {
    out.buffers["albedo"] = held.cleanAlbedo;
    out.buffers["normal"] = held.cleanNormal;
    out.auxPrefiltered = true;
  }
  return out;
}

struct Times {
  std::vector<double> alone, filter, history, total;
  std::vector<double> accumulatedFrames;
  int historyRuns = 0;
};

int run(const Args& args) {
  const torch::Device device = dn::parseDevice(args.device);
  const dn::Denoiser denoiser = dn::Denoiser::fromFile(args.model);
  dn::DenoiseOptions options;  // dndenoise's defaults
  options.device = device;
  options.precision = args.precision;
  dn::FrameBuffers input = dn::npy::readFrameFolder(args.input);
  {  // only what a sequence's frame is read with
    dn::FrameBuffers needed;
    for (const auto& name : denoiser.buffersToRead(input.names(), options))
      needed.buffers[name] = input.get(name);
    needed.width = input.width, needed.height = input.height;
    needed.dataWindow = needed.displayWindow = input.dataWindow;
    input = std::move(needed);
  }
  const dn::Image clean = denoiser.denoise(input, options).color;  // also the warm-up
  const Shot shot(input, clean, args);
  const dn::motion::MotionField motion = shot.motion();
  dn::temporal::TemporalOptions filter;
  filter.radius = args.radius;
  filter.threads = at::get_num_threads();  // as dndenoise sets it
  const int r = args.radius;

  std::map<int, Held> window;
  Times times;
  auto guide = [](const dn::FrameBuffers& f, const char* name) {
    return f.has(name) ? f.get(name) : dn::Image();
  };
  // Frames from r on are filtered; from 2r on their past frames have
  // histories and they are timed.
  for (int n = r; n < 2 * r + args.frames; ++n) {
    const bool timed = n >= 2 * r;
    for (int m = n - r; m <= n + r; ++m) {
      if (window.count(m)) continue;
      Held held;
      held.buffers = shot.frame(m);  // not timed: a sequence reads its files
      const auto start = std::chrono::steady_clock::now();
      dn::DenoiseResult alone = denoiser.denoise(held.buffers, options);
      if (timed) times.alone.push_back(secondsSince(start));
      held.frame.denoised = std::move(alone.color);
      held.frame.noisy = held.buffers.get("color");
      held.frame.guides = {guide(held.buffers, "albedo"), guide(held.buffers, "normal"),
                           guide(held.buffers, "depth")};
      held.frame.motion = motion;
      held.cleanAlbedo = std::move(alone.cleanAlbedo);
      held.cleanNormal = std::move(alone.cleanNormal);
      window.emplace(m, std::move(held));
    }
    auto start = std::chrono::steady_clock::now();
    std::vector<const dn::temporal::WindowFrame*> frames;
    for (int m = n - r; m <= n + r; ++m) frames.push_back(&window.at(m).frame);
    dn::temporal::TemporalResult result = dn::temporal::filterFrame(frames, r, filter);
    double filterTime = secondsSince(start);
    Held& self = window.at(n);
    start = std::chrono::steady_clock::now();
    const bool accumulated = result.stats.accumulatedFrames > 1.0;
    self.frame.history =
        accumulated ? denoiser.denoise(withHistory(self, std::move(result.history)), options).color
                    : self.frame.denoised;
    const double historyTime = secondsSince(start);
    start = std::chrono::steady_clock::now();
    const dn::Image blended = dn::temporal::blendWithHistory(
        result.color, dn::temporal::historyMean(self.frame.history, result, filter),
        filter.accumulatedShare);
    filterTime += secondsSince(start);
    if (timed) {
      times.filter.push_back(filterTime);
      times.history.push_back(historyTime);
      times.total.push_back(times.alone.back() + filterTime + historyTime);
      times.accumulatedFrames.push_back(result.stats.accumulatedFrames);
      times.historyRuns += accumulated;
    }
    if (blended.pixels.size() != clean.pixels.size()) throw std::logic_error("blend: wrong size");
    window.erase(n - r);  // behind the next frame's window
  }

  const std::string size = std::to_string(input.width) + "x" + std::to_string(input.height);
  const double alone = median(times.alone), total = median(times.total);
  std::printf(
      "%s, %s, %s, radius %d, %d frames timed after %d: frame by frame %.4f s, "
      "temporal %.4f s a frame (filter %.4f s on the CPU, history %.4f s), %.2fx; "
      "accumulated over %.1f frames\n",
      size.c_str(), device.str().c_str(), dn::precisionName(args.precision), r, args.frames, r,
      alone, total, median(times.filter), median(times.history), total / alone,
      median(times.accumulatedFrames));
  std::printf(
      "RESULT mode=temporal device=%s size=%s precision=%s radius=%d frames=%d median_s=%.4f "
      "alone_s=%.4f ratio=%.2f filter_s=%.4f history_s=%.4f history_runs=%d "
      "accumulated_frames=%.2f threads=%d\n",
      device.str().c_str(), size.c_str(), dn::precisionName(args.precision), r, args.frames, total,
      alone, total / alone, median(times.filter), median(times.history), times.historyRuns,
      median(times.accumulatedFrames), at::get_num_threads());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(parseArgs(argc, argv));
  } catch (const UsageError& e) {
    if (*e.what()) std::fprintf(stderr, "temporal_npy_bench: %s\n", e.what());
    std::fprintf(stderr,
                 "usage: temporal_npy_bench --input DIR [--model PATH] [--device cpu|cuda]\n"
                 "  [--precision float|bf16|fp16] [--radius 1-8] [--frames N] [--motion DX,DY]\n");
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "temporal_npy_bench: %s\n", e.what());
    return 1;
  }
}
