// The inference core on raw .npy buffers, without OpenImageIO: the OIDN base
// in its modes (one network; the prefilter mode; the light-path split; the
// Control Module forced on; `default`: DenoiseOptions as dndenoise runs them,
// the prefilter mode with the Control Module's gate) on each device asked for, timed as the median
// of N runs after warm-up, the outputs written as .npy and compared with the first device's (PSNR
// as dnmetrics computes it). Made for the GPU machine (bench/gpu/check_cuda.sh), which has a CUDA
// LibTorch but no image I/O.
//
//   denoise_npy_bench --input DIR [--model models/default.dnm]
//       [--modes base,prefilter,split,control,default] [--devices cpu,cuda]
//       [--repeats N] [--warmup N] [--threads N] [--tf32 on|off] [--output DIR]
//       [--reference DIR] [--precision float|bf16|fp16] [--cudnn-benchmark on|off]
//       [--max-memory GB] [--trace DIR]
//
// DIR holds one file per buffer, named by its canonical name (color.npy,
// albedo.npy, normal.npy, diffuse_direct.npy, ...), each (height, width,
// channels) float32 or float16. Outputs are written as OUT/<mode>_<device>.npy;
// --reference DIR compares with DIR/<mode>_cpu.npy (an earlier CPU run) instead
// of this run's first device. --trace DIR profiles one more run of each mode
// with LibTorch's Kineto profiler (CPU operators and CUDA kernels) and writes
// its Chrome trace as DIR/<mode>_<device>.json (bench/gpu/trace_summary.py
// reads it). --max-memory GB replaces the networks' memory budget (on CUDA
// by default half the GPU's free memory). Lines "RESULT key=value ..." are
// for scripts.
#include <torch/csrc/autograd/profiler_kineto.h>
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "dn/infer/denoiser.h"
#include "dn/infer/device.h"
#include "dn/io/npy.h"
#include "dn/metrics.h"

namespace fs = std::filesystem;

namespace {

struct Args {
  std::string input, output, reference, trace, model = "models/default.dnm";
  std::vector<std::string> modes = {"base", "prefilter", "split", "control"};
  std::vector<std::string> devices = {"cpu"};
  int repeats = 3, warmup = 1, threads = 0;
  bool tf32 = true;  // LibTorch's default for cuDNN convolutions
  dn::Precision precision = dn::Precision::Float;
  bool cudnnBenchmark = dn::DenoiseOptions().cudnnBenchmark;
  double maxMemoryGB = 0;  // 0: DenoiseOptions' default
};

struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

std::vector<std::string> splitList(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream stream(text);
  for (std::string item; std::getline(stream, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

int positive(const std::string& flag, const std::string& value, int least) {
  try {
    std::size_t used = 0;
    const int n = std::stoi(value, &used);
    if (used == value.size() && n >= least) return n;
  } catch (const std::exception&) {
  }
  throw UsageError(flag + " needs an integer >= " + std::to_string(least) + ", got '" + value +
                   "'");
}

Args parseArgs(int argc, char** argv) {
  Args args;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "-h" || flag == "--help") throw UsageError("");
    if (i + 1 >= argc) throw UsageError(flag + " needs a value (or is unknown)");
    const std::string value = argv[++i];
    if (flag == "--input")
      args.input = value;
    else if (flag == "--output")
      args.output = value;
    else if (flag == "--reference")
      args.reference = value;
    else if (flag == "--model")
      args.model = value;
    else if (flag == "--modes")
      args.modes = splitList(value);
    else if (flag == "--devices")
      args.devices = splitList(value);
    else if (flag == "--repeats")
      args.repeats = positive(flag, value, 1);
    else if (flag == "--warmup")
      args.warmup = positive(flag, value, 0);
    else if (flag == "--threads")
      args.threads = positive(flag, value, 1);
    else if (flag == "--tf32" && (value == "on" || value == "off"))
      args.tf32 = value == "on";
    else if (flag == "--precision" && dn::precisionFromName(value))
      args.precision = *dn::precisionFromName(value);
    else if (flag == "--cudnn-benchmark" && (value == "on" || value == "off"))
      args.cudnnBenchmark = value == "on";
    else if (flag == "--max-memory")
      args.maxMemoryGB = positive(flag, value, 1);
    else if (flag == "--trace")
      args.trace = value;
    else
      throw UsageError("unknown argument " + flag + " " + value);
  }
  if (args.input.empty()) throw UsageError("--input DIR is required");
  for (const auto& mode : args.modes)
    if (mode != "base" && mode != "prefilter" && mode != "split" && mode != "control" &&
        mode != "default")
      throw UsageError("unknown mode '" + mode + "' (base, prefilter, split, control, default)");
  if (args.modes.empty() || args.devices.empty()) throw UsageError("no modes or no devices");
  return args;
}

dn::DenoiseOptions optionsFor(const std::string& mode, torch::Device device, const Args& args) {
  dn::DenoiseOptions options;
  options.device = device;
  options.precision = args.precision;
  options.cudnnBenchmark = args.cudnnBenchmark;
  options.returnCleanAux = false;  // as dndenoise denoises single frames
  if (args.maxMemoryGB > 0) {
    options.maxMemoryBytes = args.maxMemoryGB * 1e9;
    options.budgetFromFreeMemory = false;
  }
  if (mode == "default") return options;
  options.control = mode == "control" ? dn::ControlUse::Always : dn::ControlUse::Never;
  options.prefilter = mode != "base";
  // The module forced on over the defaults (it decides itself what it cleans).
  options.lightPaths = mode == "split" || mode == "control";
  return options;
}

// The result is the mode asked for, or the input cannot give it.
void checkMode(const std::string& mode, const dn::DenoiseResult& result) {
  if (mode == "prefilter" && !result.prefiltered)
    throw std::runtime_error("prefilter: the input needs albedo.npy and normal.npy");
  if (mode == "split" && !result.lightPathsSplit)
    throw std::runtime_error(
        "split: the input needs diffuse_direct, diffuse_indirect and diffuse_color .npy");
  if (mode == "control" && !result.steered)
    throw std::runtime_error("control: the model has no Control Module for these buffers");
}

double seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// One call of fn under the Kineto profiler, its Chrome trace written to path.
void traced(const std::string& path, const std::function<void()>& fn) {
  namespace profiler = torch::autograd::profiler;
  using torch::profiler::impl::ActivityType;
  const torch::profiler::impl::ProfilerConfig config(torch::profiler::impl::ProfilerState::KINETO);
  std::set<ActivityType> activities = {ActivityType::CPU};
  if (torch::cuda::is_available()) activities.insert(ActivityType::CUDA);
  try {
    profiler::prepareProfiler(config, activities);
    profiler::enableProfiler(config, activities);
    fn();
    profiler::disableProfiler()->save(path);
  } catch (const c10::Error& e) {  // e.g. a LibTorch built without Kineto (Debian's)
    throw std::runtime_error(std::string("--trace: ") + e.what_without_backtrace());
  }
}

double median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

int run(const Args& args) {
  if (args.threads > 0) at::set_num_threads(args.threads);
  std::vector<torch::Device> devices;
  for (const auto& name : args.devices) devices.push_back(dn::parseDevice(name));
  const bool cuda =
      std::any_of(devices.begin(), devices.end(), [](auto& d) { return d.is_cuda(); });
  const char* tf32 = !cuda ? "n/a" : args.tf32 ? "on" : "off";
  if (cuda) {
    at::globalContext().setAllowTF32CuDNN(args.tf32);
    at::globalContext().setAllowTF32CuBLAS(args.tf32);
    at::globalContext().setBenchmarkCuDNN(args.cudnnBenchmark);
  }
  const dn::FrameBuffers frame = dn::npy::readFrameFolder(args.input);
  const dn::Denoiser denoiser = dn::Denoiser::fromFile(args.model);
  if (!args.output.empty()) fs::create_directories(args.output);
  const std::string size = std::to_string(frame.width) + "x" + std::to_string(frame.height);
  const char* precision = dn::precisionName(args.precision);
  std::printf("%s, %zu buffers, %s, %d CPU thread(s), %s, TF32 %s, median of %d after %d warm-up\n",
              size.c_str(), frame.buffers.size(), args.model.c_str(), at::get_num_threads(),
              precision, tf32, args.repeats, args.warmup);
  std::printf("%-10s %-8s %10s %10s %12s\n", "mode", "device", "median s", "min s", "PSNR vs ref");

  for (const auto& mode : args.modes) {
    dn::Image reference;
    std::string referenceName = args.devices[0];
    if (!args.reference.empty()) {
      reference = dn::npy::readImage(args.reference + "/" + mode + "_cpu.npy");
      referenceName = "cpu";
    }
    for (std::size_t d = 0; d < devices.size(); ++d) {
      const dn::DenoiseOptions options = optionsFor(mode, devices[d], args);
      dn::DenoiseResult result;
      for (int i = 0; i < args.warmup; ++i) result = denoiser.denoise(frame, options);
      std::vector<double> times;
      for (int i = 0; i < args.repeats; ++i) {
        const auto start = std::chrono::steady_clock::now();
        result = denoiser.denoise(frame, options);  // returns host memory: synchronised
        times.push_back(seconds(start));
      }
      checkMode(mode, result);
      if (!args.trace.empty()) {
        fs::create_directories(args.trace);
        traced(args.trace + "/" + mode + "_" + args.devices[d] + ".json",
               [&] { denoiser.denoise(frame, options); });
      }
      const std::string device = devices[d].str();
      if (!args.output.empty())
        dn::npy::writeImage(args.output + "/" + mode + "_" + args.devices[d] + ".npy",
                            result.color);
      const bool compared = !reference.empty();
      const double psnr =
          compared ? dn::metrics::compare(reference, result.color, {"psnr"}).values.at("psnr") : 0;
      if (reference.empty()) reference = result.color;
      const double best = *std::min_element(times.begin(), times.end());
      std::printf("%-10s %-8s %10.3f %10.3f %12s\n", mode.c_str(), device.c_str(), median(times),
                  best, compared ? std::to_string(psnr).c_str() : "-");
      std::printf(
          "RESULT mode=%s device=%s size=%s precision=%s tf32=%s cudnn_benchmark=%s "
          "memory_gb=%g tiles=%zu steered=%d threads=%d repeats=%d median_s=%.4f min_s=%.4f",
          mode.c_str(), device.c_str(), size.c_str(), precision, tf32,
          cuda ? (args.cudnnBenchmark ? "on" : "off") : "n/a", args.maxMemoryGB, result.tileCount,
          int(result.steered), at::get_num_threads(), args.repeats, median(times), best);
      if (compared) std::printf(" psnr_vs_%s=%.2f", referenceName.c_str(), psnr);
      std::printf("\n");
      std::fflush(stdout);
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(parseArgs(argc, argv));
  } catch (const UsageError& e) {
    if (*e.what()) std::fprintf(stderr, "denoise_npy_bench: %s\n", e.what());
    std::fprintf(
        stderr,
        "usage: denoise_npy_bench --input DIR [--model PATH] [--modes base,prefilter,split,"
        "control,default]\n  [--devices cpu,cuda] [--repeats N] [--warmup N] [--threads N] "
        "[--tf32 on|off] [--output DIR] [--reference DIR] [--precision float|bf16|fp16]\n"
        "  [--cudnn-benchmark on|off] [--max-memory GB] [--trace DIR]\n");
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "denoise_npy_bench: %s\n", e.what());
    return 1;
  }
}
