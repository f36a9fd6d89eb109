// Data loader throughput: samples per second of dn::data::Loader on a data set
// (default: the committed sample), cold (decoding) and warm (cached frames).
//   loader_bench [DATA_DIR] [--crop 64] [--batch 8] [--threads 2] [--batches 50]
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>

#include "dn/data/dataset.h"
#include "dn/io/buffers.h"

using namespace dn::data;

int main(int argc, char** argv) {
  std::string root = DN_TESTDATA "/dataset";
  int crop = 64, batch = 8, threads = 2, batches = 50;
  for (int i = 1; i < argc; ++i) {
    auto next = [&] { return i + 1 < argc ? std::atoi(argv[++i]) : 0; };
    if (!std::strcmp(argv[i], "--crop"))
      crop = next();
    else if (!std::strcmp(argv[i], "--batch"))
      batch = next();
    else if (!std::strcmp(argv[i], "--threads"))
      threads = next();
    else if (!std::strcmp(argv[i], "--batches"))
      batches = next();
    else
      root = argv[i];
  }
  auto frames = scanDataset(root, "train");
  int maxSpp = 1 << 30;
  for (const auto& f : frames) maxSpp = std::min(maxSpp, f.stacks * f.stackSpp);
  SampleOptions so;
  so.spp = {4};
  if (maxSpp >= 16) so.spp.push_back(16);
  if (maxSpp >= 64) so.spp.push_back(64);
  so.aux = dn::defaultAuxBuffers();
  so.crop = crop;
  LoaderOptions lo;
  lo.batchSize = batch;
  lo.threads = threads;
  Loader loader(frames, so, lo);
  using Clock = std::chrono::steady_clock;
  auto t0 = Clock::now();
  loader.next();
  double first = std::chrono::duration<double>(Clock::now() - t0).count();
  t0 = Clock::now();
  for (int b = 0; b < batches; ++b) loader.next();
  double rest = std::chrono::duration<double>(Clock::now() - t0).count();
  std::printf("loader: %zu frames, crop %d, batch %d, %d threads, spp up to %d, 34 aux channels\n",
              frames.size(), crop, batch, threads, so.spp.back());
  std::printf("first batch (cold, decoding EXRs): %.3f s\n", first);
  std::printf("steady state: %.1f samples/s over %d batches\n", batches * batch / rest, batches);
  return 0;
}
