// score REF TEST: L1 and PSNR of TEST against REF, read with dn::io and scored
// with dn::metrics. Prints "l1 V" and "psnr V".
#include <cstdio>
#include <exception>

#include "dn/io/buffer_io.h"
#include "dn/metrics.h"

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fputs("usage: score REF TEST\n", stderr);
    return 1;
  }
  try {
    const dn::Image reference = dn::readImage(argv[1], 3);
    const dn::Image test = dn::readImage(argv[2], 3);
    const auto values = dn::metrics::compare(reference, test, {"l1", "psnr"}).values;
    std::printf("l1 %.8g\npsnr %.8g\n", values.at("l1"), values.at("psnr"));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "score: %s\n", e.what());
    return 1;
  }
  return 0;
}
