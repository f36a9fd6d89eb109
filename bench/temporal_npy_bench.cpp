// The temporal default's cost per frame against frame-by-frame denoising, on
// a synthetic shot made from one frame of .npy buffers (as denoise_npy_bench
// reads them), without OpenImageIO: for the GPU machine (bench/gpu/check_cuda.sh).
//
//   temporal_npy_bench --input DIR [--model models/default.dnm] [--device cpu|cuda]
//       [--precision float|bf16|fp16] [--radius 4] [--frames 3] [--motion 3,2]
//       [--filter cpu|device]
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
// networks run on the device; the filter too where --filter device (the
// default with --device cuda, as dndenoise runs it: dn/temporal/device_filter.h,
// each frame copied there once as it enters the window), else on the CPU
// (dn::temporal::filterFrame). The device filter's result is compared once
// with the CPU's (filter_max_diff, filter_psnr_db). Frames are timed once
// `radius` frames have their histories (the steady state); making the
// synthetic frames is not timed. Lines "RESULT key=value ..." are for scripts.
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "dn/infer/denoiser.h"
#include "dn/infer/device.h"
#include "dn/io/npy.h"
#include "dn/temporal/device_filter.h"
#include "dn/temporal/temporal_filter.h"

namespace {

struct Args {
  std::string input, model = "models/default.dnm", device = "cpu";
  dn::Precision precision = dn::Precision::Float;
  int radius = dn::temporal::TemporalOptions().radius;
  int frames = 3;
  int dx = 3, dy = 2;  // pixels a frame
  std::string filter;  // cpu or device; empty: device on CUDA, else cpu
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
    } else if (flag == "--filter" && (value == "cpu" || value == "device")) {
      args.filter = value;
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
  dn::temporal::DeviceFrame onDevice;  // --filter device: the frame there
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

// One frame past the networks' first run: its filtered colour, blended with
// its accumulated render denoised, and what each part took.
struct Step {
  dn::Image color;
  double filter = 0.0, history = 0.0;  // seconds
  double accumulatedFrames = 1.0;
};

// The window's frames, its centre `n`, and how its history is denoised.
struct Frame {
  std::map<int, Held>& window;
  int n, radius;
  const dn::Denoiser& denoiser;
  const dn::DenoiseOptions& options;
  const dn::temporal::TemporalOptions& filter;
};

std::vector<const dn::temporal::WindowFrame*> hostWindow(const Frame& f) {
  std::vector<const dn::temporal::WindowFrame*> frames;
  for (int m = f.n - f.radius; m <= f.n + f.radius; ++m) frames.push_back(&f.window.at(m).frame);
  return frames;
}

// The frame's accumulated render denoised, or its own result where nothing was accumulated.
dn::Image denoisedHistory(const Frame& f, dn::Image accumulated, double accumulatedFrames) {
  Held& self = f.window.at(f.n);
  return accumulatedFrames > 1.0
             ? f.denoiser.denoise(withHistory(self, std::move(accumulated)), f.options).color
             : self.frame.denoised.toImage();
}

Step onCpu(const Frame& f) {
  Step step;
  auto start = std::chrono::steady_clock::now();
  dn::temporal::TemporalResult result =
      dn::temporal::filterFrame(hostWindow(f), f.radius, f.filter);
  step.filter = secondsSince(start);
  Held& self = f.window.at(f.n);
  start = std::chrono::steady_clock::now();
  step.accumulatedFrames = result.stats.accumulatedFrames;
  self.frame.history = denoisedHistory(f, std::move(result.history), step.accumulatedFrames);
  step.history = secondsSince(start);
  start = std::chrono::steady_clock::now();
  step.color = dn::temporal::blendWithHistory(
      result.color, dn::temporal::historyMean(self.frame.history.floats(), result, f.filter),
      f.filter.accumulatedShare);
  step.filter += secondsSince(start);
  return step;
}

// The same on the device: each frame copied there as it enters the window
// (timed with the filter), its history once denoised, the colour copied back.
Step onDevice(const Frame& f, const torch::Device& device) {
  Step step;
  auto start = std::chrono::steady_clock::now();
  std::vector<const dn::temporal::DeviceFrame*> frames;
  for (int m = f.n - f.radius; m <= f.n + f.radius; ++m) {
    Held& held = f.window.at(m);
    if (!held.onDevice.denoised.defined())
      held.onDevice = dn::temporal::toDevice(held.frame, device);
    frames.push_back(&held.onDevice);
  }
  const dn::temporal::DeviceTemporalResult result =
      dn::temporal::filterFrame(frames, f.radius, f.filter);
  Held& self = f.window.at(f.n);
  const int w = self.frame.denoised.width(), h = self.frame.denoised.height();
  dn::Image accumulated = dn::temporal::pixelsToImage(result.history, w, h);
  step.filter = secondsSince(start);
  start = std::chrono::steady_clock::now();
  step.accumulatedFrames = result.stats.accumulatedFrames;
  self.frame.history = denoisedHistory(f, std::move(accumulated), step.accumulatedFrames);
  self.onDevice.history = dn::temporal::pixelsToDevice(self.frame.history.floats(), device);
  step.history = secondsSince(start);
  start = std::chrono::steady_clock::now();
  const torch::Tensor blended = dn::temporal::blendWithHistory(
      result.color, dn::temporal::historyMean(self.onDevice.history, result, f.filter),
      f.filter.accumulatedShare);
  step.color = dn::temporal::pixelsToImage(blended, w, h);
  step.filter += secondsSince(start);
  return step;
}

// The device filter's colour against filterFrame's on the same window:
// max |difference| and PSNR over the CPU's peak.
std::pair<double, double> filterAgreement(const Frame& f, const torch::Device& device) {
  std::vector<dn::temporal::DeviceFrame> copies;
  std::vector<const dn::temporal::DeviceFrame*> frames;
  const std::vector<const dn::temporal::WindowFrame*> host = hostWindow(f);
  copies.reserve(host.size());
  for (const auto* frame : host) copies.push_back(dn::temporal::toDevice(*frame, device));
  for (const auto& copy : copies) frames.push_back(&copy);
  const dn::Image reference = dn::temporal::filterFrame(host, f.radius, f.filter).color;
  const dn::Image color =
      dn::temporal::pixelsToImage(dn::temporal::filterFrame(frames, f.radius, f.filter).color,
                                  reference.width, reference.height);
  double worst = 0.0, squares = 0.0, peak = 1e-12;
  for (std::size_t i = 0; i < color.pixels.size(); ++i) {
    const double d = double(color.pixels[i]) - reference.pixels[i];
    worst = std::max(worst, std::abs(d));
    squares += d * d;
    peak = std::max(peak, std::abs(double(reference.pixels[i])));
  }
  const double mse = squares / std::max<std::size_t>(1, color.pixels.size());
  return {worst, mse > 0.0 ? 10.0 * std::log10(peak * peak / mse) : 999.0};
}

int run(const Args& args) {
  const torch::Device device = dn::parseDevice(args.device);
  const bool filterOnDevice = args.filter.empty() ? device.is_cuda() : args.filter == "device";
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
  std::pair<double, double> agreement{0.0, 0.0};
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
      held.frame.guides =
          dn::motion::Guides{guide(held.buffers, "albedo"), guide(held.buffers, "normal"),
                             guide(held.buffers, "depth")};
      held.frame.motion = motion;
      held.cleanAlbedo = std::move(alone.cleanAlbedo);
      held.cleanNormal = std::move(alone.cleanNormal);
      window.emplace(m, std::move(held));
    }
    const Frame frame{window, n, r, denoiser, options, filter};
    if (timed && filterOnDevice && times.filter.empty())
      agreement = filterAgreement(frame, device);  // not timed
    const Step step = filterOnDevice ? onDevice(frame, device) : onCpu(frame);
    if (timed) {
      times.filter.push_back(step.filter);
      times.history.push_back(step.history);
      times.total.push_back(times.alone.back() + step.filter + step.history);
      times.accumulatedFrames.push_back(step.accumulatedFrames);
      times.historyRuns += step.accumulatedFrames > 1.0;
    }
    if (step.color.pixels.size() != clean.pixels.size())
      throw std::logic_error("blend: wrong size");
    window.erase(n - r);  // behind the next frame's window
  }

  const std::string size = std::to_string(input.width) + "x" + std::to_string(input.height);
  const double alone = median(times.alone), total = median(times.total);
  const std::string where = filterOnDevice ? device.str() : "cpu";
  const char* path = filterOnDevice ? "device" : "cpu";
  std::printf(
      "%s, %s, %s, radius %d, %d frames timed after %d: frame by frame %.4f s, "
      "temporal %.4f s a frame (filter %.4f s, %s path on %s, history %.4f s), %.2fx; "
      "accumulated over %.1f frames\n",
      size.c_str(), device.str().c_str(), dn::precisionName(args.precision), r, args.frames, r,
      alone, total, median(times.filter), path, where.c_str(), median(times.history), total / alone,
      median(times.accumulatedFrames));
  if (filterOnDevice)
    std::printf("the device filter against the CPU's: max |difference| %.2e, PSNR %.1f dB\n",
                agreement.first, agreement.second);
  std::printf(
      "RESULT mode=temporal device=%s size=%s precision=%s radius=%d frames=%d median_s=%.4f "
      "alone_s=%.4f ratio=%.2f filter_s=%.4f history_s=%.4f history_runs=%d "
      "accumulated_frames=%.2f threads=%d filter_path=%s filter_device=%s",
      device.str().c_str(), size.c_str(), dn::precisionName(args.precision), r, args.frames, total,
      alone, total / alone, median(times.filter), median(times.history), times.historyRuns,
      median(times.accumulatedFrames), at::get_num_threads(), path, where.c_str());
  if (filterOnDevice)
    std::printf(" filter_max_diff=%.3g filter_psnr_db=%.1f", agreement.first, agreement.second);
  std::printf("\n");
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
                 "  [--precision float|bf16|fp16] [--radius 1-8] [--frames N] [--motion DX,DY]\n"
                 "  [--filter cpu|device]\n");
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "temporal_npy_bench: %s\n", e.what());
    return 1;
  }
}
