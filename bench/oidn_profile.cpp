// Where the pretrained OIDN base spends its time on one frame: the stages of
// runOidn (input, network, output) timed separately, then the network's
// operators from LibTorch's profiler (time including the operators they call,
// and calls, for one forward pass).
//
//   oidn_profile --model models/oidn.dnm FRAME.exr [--threads N] [--repeats N]
#include <torch/csrc/autograd/profiler_legacy.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <map>
#include <string>
#include <vector>

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

}  // namespace

int main(int argc, char** argv) {
  std::string model, frame;
  int threads = 2, repeats = 3;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--model" && i + 1 < argc)
      model = argv[++i];
    else if (a == "--threads" && i + 1 < argc)
      threads = std::atoi(argv[++i]);
    else if (a == "--repeats" && i + 1 < argc)
      repeats = std::max(1, std::atoi(argv[++i]));
    else
      frame = a;
  }
  if (model.empty() || frame.empty()) {
    std::fprintf(stderr,
                 "usage: oidn_profile --model FILE FRAME.exr [--threads N] [--repeats N]\n");
    return 2;
  }
  torch::set_num_threads(threads);
  c10::InferenceMode inference;
  LoadedModel loaded = loadModelFile(model);
  loaded.oidn->eval();
  loaded.oidn->useChannelsLast();
  const FrameBuffers buffers = readFrame(frame);
  auto [net, set] = loaded.oidn->pick(buffers.names());
  const float exposure = tonemap::oidnExposure(buffers.get("color"));
  const TileRect all{0, 0, buffers.height, buffers.width};
  const double mpix = buffers.width * double(buffers.height) / 1e6;
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
