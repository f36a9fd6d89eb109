// Where the pretrained OIDN base spends its time on one frame: the stages of
// runOidn (input, network, output) timed separately, then the network's
// operators from LibTorch's profiler (time including the operators they call,
// and calls, for one forward pass). --pipeline times, instead, each network
// of the default's prefilter mode and light-path split (alb, nrm, the large
// network, ...) and the image work between them, once each. --bf16 runs the
// networks in bfloat16.
//
//   oidn_profile --model models/oidn.dnm FRAME.exr [--threads N] [--repeats N]
//                [--set INPUT_SET] [--pipeline] [--bf16]
#include <torch/csrc/autograd/profiler_legacy.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "dn/infer/light_paths.h"
#include "dn/infer/oidn_filter.h"
#include "dn/io/buffer_io.h"
#include "dn/nn/model_file.h"
#include "dn/tonemap.h"

using namespace dn;

namespace {

using Clock = std::chrono::steady_clock;

// Median seconds of `repeats` runs of fn.
double medianSeconds(int repeats, const std::function<void()>& fn) {
  std::vector<double> s;
  for (int i = 0; i < repeats; ++i) {
    auto start = Clock::now();
    fn();
    s.push_back(std::chrono::duration<double>(Clock::now() - start).count());
  }
  std::sort(s.begin(), s.end());
  return s[s.size() / 2];
}

// Inclusive milliseconds and calls per operator name, from the profiler's
// push/pop pairs on the calling thread.
void printOperators(const torch::autograd::profiler::thread_event_lists& lists, double mpix) {
  using torch::autograd::profiler::EventKind;
  using torch::autograd::profiler::LegacyEvent;
  struct Total {
    double ms = 0;
    int calls = 0;
    int depth = 0;
  };
  std::map<std::string, Total> totals;
  for (const auto& list : lists) {
    std::vector<const LegacyEvent*> stack;
    for (const auto& e : list) {
      if (e.kind() == EventKind::PushRange) {
        stack.push_back(&e);
      } else if (e.kind() == EventKind::PopRange && !stack.empty()) {
        const LegacyEvent* start = stack.back();
        stack.pop_back();
        Total& t = totals[start->name()];
        t.ms += start->cpuElapsedUs(e) / 1000.0;
        t.calls += 1;
        t.depth = int(stack.size());
      }
    }
  }
  std::vector<std::pair<std::string, Total>> rows(totals.begin(), totals.end());
  std::sort(rows.begin(), rows.end(),
            [](const auto& a, const auto& b) { return a.second.ms > b.second.ms; });
  std::printf("%-40s %10s %10s %6s %5s\n", "operator (inclusive)", "ms", "s/MPix", "calls",
              "depth");
  for (const auto& [name, t] : rows)
    if (t.ms >= 1.0)
      std::printf("%-40s %10.1f %10.3f %6d %5d\n", name.c_str(), t.ms, t.ms / 1000.0 / mpix,
                  t.calls, t.depth);
}

// Every step of the default (runOidnPrefiltered with the split), timed once.
void profilePipeline(const OidnBase& base, const FrameBuffers& frame, double mpix) {
  using namespace std::chrono;
  double total = 0;
  auto step = [&](const std::string& name, const std::function<void()>& fn) {
    const double s = medianSeconds(1, fn);
    total += s;
    std::printf("%-40s %8.3f s %8.3f s/MPix\n", name.c_str(), s, s / mpix);
  };
  auto run = [&](const char* setName, const FrameBuffers& in) {
    OidnUNet net = base->net(setName);
    return runOidn(net, oidnInputSet(setName), in, OidnRunOptions()).image;
  };
  auto toImage = [](const torch::Tensor& t) {
    const auto chw = t.squeeze(0);
    Image image(int(chw.size(2)), int(chw.size(1)), int(chw.size(0)));
    torch::from_blob(image.pixels.data(), {image.height, image.width, image.channels})
        .copy_(chw.permute({1, 2, 0}));
    return image;
  };
  FrameBuffers clean = frame, part;
  part.width = frame.height;
  part.height = frame.width;
  torch::Tensor whole, diffuse, rest;
  LightPathSplit split;
  step("alb (albedo)", [&] { clean.buffers["albedo"] = toImage(run("alb", frame)); });
  step("nrm (normal)", [&] { clean.buffers["normal"] = toImage(run("nrm", frame)); });
  step("large (whole frame)", [&] { whole = run("hdr_calb_cnrm_large", clean); });
  step("split + transposes", [&] {
    split = splitDiffuse(frame);
    part.buffers["albedo"] = transposed(frame.get("diffuse_color"));
    part.buffers["normal"] = transposed(clean.get("normal"));
    part.buffers["color"] = transposed(split.diffuse);
  });
  step("alb (diffuse colour)", [&] { part.buffers["albedo"] = toImage(run("alb", part)); });
  step("large (diffuse part)", [&] { diffuse = run("hdr_calb_cnrm_large", part); });
  step("large (rest)", [&] {
    part.buffers["albedo"] = transposed(clean.get("albedo"));
    part.buffers["color"] = transposed(split.rest);
    rest = run("hdr_calb_cnrm_large", part);
  });
  step("average", [&] { whole = 0.5 * (whole + (diffuse + rest).transpose(2, 3)); });
  std::printf("%-40s %8.3f s %8.3f s/MPix\n", "total", total, total / mpix);
}

}  // namespace

int main(int argc, char** argv) {
  std::string model, frame, setName;
  int threads = 2, repeats = 3;
  bool pipeline = false, bf16 = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--model" && i + 1 < argc)
      model = argv[++i];
    else if (a == "--threads" && i + 1 < argc)
      threads = std::atoi(argv[++i]);
    else if (a == "--repeats" && i + 1 < argc)
      repeats = std::max(1, std::atoi(argv[++i]));
    else if (a == "--set" && i + 1 < argc)
      setName = argv[++i];
    else if (a == "--pipeline")
      pipeline = true;
    else if (a == "--bf16")
      bf16 = true;
    else
      frame = a;
  }
  if (model.empty() || frame.empty()) {
    std::fprintf(stderr,
                 "usage: oidn_profile --model FILE FRAME.exr [--threads N] [--repeats N] "
                 "[--set INPUT_SET] [--pipeline] [--bf16]\n");
    return 2;
  }
  torch::set_num_threads(threads);
  LoadedModel loaded = loadModelFile(model);  // outside inference mode, as the Denoiser loads it
  OidnBase base = loaded.oidnControlled ? loaded.oidnControlled->base() : loaded.oidn;
  base->eval();
  base->useChannelsLast();
  base->useBFloat16(bf16);
  const FrameBuffers buffers = readFrame(frame);
  c10::InferenceMode inference;
  const double mpix = buffers.width * double(buffers.height) / 1e6;
  if (pipeline) {
    std::printf("%dx%d, the default's networks, %d threads%s\n", buffers.width, buffers.height,
                threads, bf16 ? ", bfloat16" : "");
    profilePipeline(base, buffers, mpix);
    return 0;
  }
  auto [net, set] = base->pick(buffers.names());
  if (!setName.empty()) {
    net = base->net(setName);
    set = &oidnInputSet(setName);
  }
  const float exposure = tonemap::oidnExposure(buffers.get("color"));
  const TileRect all{0, 0, buffers.height, buffers.width};
  std::printf("%dx%d, input set %s, %d threads, median of %d\n", buffers.width, buffers.height,
              set->name.c_str(), threads, repeats);

  auto stage = [&](const char* name, const std::function<void()>& fn) {
    const double s = medianSeconds(repeats, fn);
    std::printf("%-40s %8.3f s %8.3f s/MPix\n", name, s, s / mpix);
  };
  torch::Tensor x, y;
  stage("autoexposure", [&] { tonemap::oidnExposure(buffers.get("color")); });
  stage("oidnInput", [&] { x = oidnInput(buffers, *set, exposure, all); });
  torch::Tensor unpadded = x;
  stage("pad + channels-last", [&] {
    const int64_t padH = (kOidnAlignment - all.height % kOidnAlignment) % kOidnAlignment;
    const int64_t padW = (kOidnAlignment - all.width % kOidnAlignment) % kOidnAlignment;
    x = torch::constant_pad_nd(unpadded, {0, padW, 0, padH}, 0.0)
            .contiguous(torch::MemoryFormat::ChannelsLast);
  });
  stage("network forward", [&] { y = net->forward(x); });
  stage("oidnOutputDecode", [&] {
    oidnOutputDecode(y.narrow(2, 0, all.height).narrow(3, 0, all.width), *set, exposure);
  });
  OidnRunOptions options;
  options.exposure = exposure;
  stage("runOidn (all of the above)", [&] { runOidn(net, *set, buffers, options); });

  using namespace torch::autograd::profiler;
  enableProfilerLegacy(
      torch::profiler::impl::ProfilerConfig(torch::profiler::impl::ProfilerState::CPU));
  net->forward(x);
  printOperators(disableProfilerLegacy(), mpix);
  return 0;
}
