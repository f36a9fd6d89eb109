// Test-only tool: FLIP of two EXRs, printed as JSON, for
// tests/flip_reference_check.py to compare against NVIDIA's flip-evaluator.
//
//   flip_cli REFERENCE.exr TEST.exr [--dump PREFIX] [--ppd N]
//
// Prints {"flip": ..., "hdrflip": ..., ...}: "flip" is LDR-FLIP of the
// Reinhard-tonemapped (v / (1 + v), negatives as 0), sRGB-encoded images;
// "hdrflip" is HDR-FLIP of the linear images. --dump writes the linear RGB
// that was compared as PREFIX.reference.npy and PREFIX.test.npy (float32,
// height x width x 3) so the reference sees exactly the same data, and the
// magma heatmap of the LDR-FLIP map as PREFIX.flip_magma.npy.
#include <OpenImageIO/imageio.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "dn/flip.h"
#include "dn/image.h"
#include "dn/tonemap.h"

namespace {

bool endsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Indices of the R, G, B channels: plain "R","G","B", else a render layer's
// "...Combined.R" etc., else the first three channels.
std::vector<int> rgbChannels(const OIIO::ImageSpec& spec, const std::string& path) {
  if (spec.nchannels < 3) throw std::runtime_error(path + ": fewer than 3 channels");
  for (const std::string prefix : {"", "Combined."}) {
    std::vector<int> found;
    for (const char* name : {"R", "G", "B"}) {
      for (int c = 0; c < spec.nchannels; ++c) {
        const std::string& channel = spec.channelnames[c];
        const bool matches =
            prefix.empty() ? channel == name
                           : channel == prefix + name || endsWith(channel, "." + prefix + name);
        if (matches) {
          found.push_back(c);
          break;
        }
      }
    }
    if (found.size() == 3) return found;
  }
  return {0, 1, 2};
}

dn::Image readRgb(const std::string& path) {
  auto input = OIIO::ImageInput::open(path);
  if (!input) throw std::runtime_error(path + ": " + OIIO::geterror());
  const OIIO::ImageSpec& spec = input->spec();
  const std::vector<int> rgb = rgbChannels(spec, path);
  std::vector<float> all(static_cast<std::size_t>(spec.width) * spec.height * spec.nchannels);
  if (!input->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, all.data()))
    throw std::runtime_error(path + ": " + input->geterror());
  dn::Image image(spec.width, spec.height, 3);
  for (std::size_t i = 0; i < image.pixelCount(); ++i)
    for (int c = 0; c < 3; ++c) image.pixels[i * 3 + c] = all[i * spec.nchannels + rgb[c]];
  return image;
}

void writeNpy(const dn::Image& image, const std::string& path) {
  std::string header = "{'descr': '<f4', 'fortran_order': False, 'shape': (" +
                       std::to_string(image.height) + ", " + std::to_string(image.width) + ", " +
                       std::to_string(image.channels) + "), }";
  header.append(63 - (10 + header.size()) % 64, ' ');  // total header size a multiple of 64
  header += '\n';
  const std::string temporary = path + ".tmp";
  {
    std::ofstream out(temporary, std::ios::binary);
    const unsigned short headerLength = static_cast<unsigned short>(header.size());
    out.write("\x93NUMPY\x01\x00", 8);
    out.put(static_cast<char>(headerLength & 0xff));
    out.put(static_cast<char>(headerLength >> 8));
    out << header;
    out.write(reinterpret_cast<const char*>(image.pixels.data()),
              static_cast<std::streamsize>(image.pixels.size() * sizeof(float)));
    if (!out) throw std::runtime_error(path + ": cannot write");
  }
  if (std::rename(temporary.c_str(), path.c_str()) != 0)
    throw std::runtime_error(path + ": cannot rename " + temporary);
}

dn::Image reinhardSrgb(const dn::Image& linear) {
  dn::Image out = linear;
  for (float& v : out.pixels) v = dn::tonemap::srgbEncode(dn::tonemap::reinhard(v));
  return out;
}

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> files;
  std::string dumpPrefix;
  double ppd = dn::flip::kDefaultPixelsPerDegree;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--dump" && i + 1 < argc)
      dumpPrefix = argv[++i];
    else if (arg == "--ppd" && i + 1 < argc)
      ppd = std::stod(argv[++i]);
    else
      files.push_back(arg);
  }
  if (files.size() != 2) {
    std::fprintf(stderr, "usage: flip_cli REFERENCE.exr TEST.exr [--dump PREFIX] [--ppd N]\n");
    return 2;
  }
  try {
    const dn::Image reference = readRgb(files[0]);
    const dn::Image test = readRgb(files[1]);
    if (!dumpPrefix.empty()) {
      writeNpy(reference, dumpPrefix + ".reference.npy");
      writeNpy(test, dumpPrefix + ".test.npy");
    }
    auto start = std::chrono::steady_clock::now();
    const dn::Image ldr = dn::flip::ldrErrorMap(reinhardSrgb(reference), reinhardSrgb(test), ppd);
    const double ldrSeconds = secondsSince(start);
    if (!dumpPrefix.empty()) writeNpy(dn::flip::magmaHeatmap(ldr), dumpPrefix + ".flip_magma.npy");
    dn::flip::HdrOptions options;
    options.pixelsPerDegree = ppd;
    start = std::chrono::steady_clock::now();
    const dn::Image hdr = dn::flip::hdrErrorMap(reference, test, options);
    const double hdrSeconds = secondsSince(start);
    const dn::flip::ExposureRange range = dn::flip::exposureRange(reference, options);
    std::printf(
        "{\"flip\": %.9g, \"hdrflip\": %.9g, \"width\": %d, \"height\": %d, "
        "\"start_exposure\": %.9g, \"stop_exposure\": %.9g, \"num_exposures\": %d, "
        "\"flip_seconds\": %.6f, \"hdrflip_seconds\": %.6f}\n",
        dn::flip::statistics(ldr).mean, dn::flip::statistics(hdr).mean, reference.width,
        reference.height, range.start, range.stop, range.count, ldrSeconds, hdrSeconds);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "flip_cli: %s\n", e.what());
    return 1;
  }
  return 0;
}
