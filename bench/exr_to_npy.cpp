// A render's buffers as dndenoise reads them (dn/io/buffer_io.h: layer names,
// normal decoding), written one .npy per canonical buffer for the inference
// core alone (bench/denoise_npy_bench, bench/gpu/check_cuda.sh).
//
//   exr_to_npy FRAME.exr OUT_DIR [--buffers color,albedo,...] [--float16]
#include <cstdio>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "dn/io/buffer_io.h"
#include "dn/io/npy.h"

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: exr_to_npy FRAME.exr OUT_DIR [--buffers a,b,...] [--float16]\n");
    return 2;
  }
  const std::string input = argv[1], outDir = argv[2];
  std::vector<std::string> wanted;
  dn::npy::DType dtype = dn::npy::DType::Float32;
  for (int i = 3; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "--float16") {
      dtype = dn::npy::DType::Float16;
    } else if (flag == "--buffers" && i + 1 < argc) {
      std::stringstream list(argv[++i]);
      for (std::string name; std::getline(list, name, ',');) wanted.push_back(name);
    } else {
      std::fprintf(stderr, "exr_to_npy: unknown argument %s\n", flag.c_str());
      return 2;
    }
  }
  try {
    const dn::FrameBuffers frame = dn::readFrame(input);
    if (wanted.empty()) wanted = frame.names();
    for (const auto& name : wanted)
      if (!frame.has(name)) throw std::runtime_error(input + ": no " + name + " buffer");
    std::filesystem::create_directories(outDir);
    for (const auto& name : wanted) {
      dn::npy::writeImage(outDir + "/" + name + ".npy", frame.get(name), dtype);
      std::printf("%s/%s.npy\n", outDir.c_str(), name.c_str());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "exr_to_npy: %s\n", e.what());
    return 1;
  }
  return 0;
}
