#include "dn/nn/oidn_import.h"

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <regex>

#include "dn/io/sha256.h"
#include "dn/io/tza.h"

namespace dn {
namespace {

struct Expected {
  const char* name;
  OidnArch arch;
  int64_t in_channels;
};

// OIDN 2.x's weights in the order its build links them (alphabetical).
constexpr Expected kOidnWeights[] = {{"alb", OidnArch::Default, 3},
                                     {"alb_large", OidnArch::Large, 3},
                                     {"hdr", OidnArch::Default, 3},
                                     {"hdr_small", OidnArch::Small, 3},
                                     {"hdr_alb", OidnArch::Default, 6},
                                     {"hdr_alb_small", OidnArch::Small, 6},
                                     {"hdr_alb_nrm", OidnArch::Default, 9},
                                     {"hdr_alb_nrm_small", OidnArch::Small, 9},
                                     {"hdr_calb_cnrm", OidnArch::Default, 9},
                                     {"hdr_calb_cnrm_small", OidnArch::Small, 9},
                                     {"hdr_calb_cnrm_large", OidnArch::Large, 9},
                                     {"ldr", OidnArch::Default, 3},
                                     {"ldr_small", OidnArch::Small, 3},
                                     {"ldr_alb", OidnArch::Default, 6},
                                     {"ldr_alb_small", OidnArch::Small, 6},
                                     {"ldr_alb_nrm", OidnArch::Default, 9},
                                     {"ldr_alb_nrm_small", OidnArch::Small, 9},
                                     {"ldr_calb_cnrm", OidnArch::Default, 9},
                                     {"ldr_calb_cnrm_small", OidnArch::Small, 9},
                                     {"nrm", OidnArch::Default, 3},
                                     {"nrm_large", OidnArch::Large, 3},
                                     {"rtlightmap_dir", OidnArch::Default, 3},
                                     {"rtlightmap_hdr", OidnArch::Default, 3}};

std::string readBinary(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ModelError(path + ": cannot open for reading");
  std::string bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  if (in.bad()) throw ModelError(path + ": read error");
  return bytes;
}

// The blob's network, or a message saying why its tensors are not one.
bool matchesNetwork(const tza::Blob& blob, const OidnUNetConfig& config, std::string& why) {
  const auto convs = oidnConvs(config);
  if (blob.tensors.size() != 2 * convs.size()) {
    why = std::to_string(blob.tensors.size()) + " tensors, expected " +
          std::to_string(2 * convs.size());
    return false;
  }
  for (const auto& conv : convs) {
    const tza::Tensor* w = blob.find(conv.name + ".weight");
    const tza::Tensor* b = blob.find(conv.name + ".bias");
    if (!w || !b) {
      why = "no tensor '" + conv.name + ".weight' or '.bias'";
      return false;
    }
    if (w->dims != std::vector<int64_t>{conv.out, conv.in, 3, 3} || w->layout != "oihw" ||
        b->dims != std::vector<int64_t>{conv.out}) {
      why = "tensor '" + conv.name + "' has an unexpected shape";
      return false;
    }
  }
  return true;
}

void copyWeights(const tza::Blob& blob, OidnUNet& net) {
  torch::NoGradGuard noGrad;
  for (auto& item : net->named_parameters()) {
    const tza::Tensor* t = blob.find(item.key());
    auto values = torch::from_blob(const_cast<float*>(t->values.data()),
                                   {static_cast<int64_t>(t->values.size())}, torch::kFloat32);
    item.value().copy_(values.view(item.value().sizes()));
  }
}

std::string libraryVersion(const std::string& path) {
  std::smatch match;
  const std::string name = std::filesystem::path(path).filename().string();
  return std::regex_search(name, match, std::regex(R"(\.so\.(\d+\.\d+\.\d+)$)")) ? match[1].str()
                                                                                 : "unknown";
}

}  // namespace

std::vector<OidnWeights> listOidnWeights(const std::string& libraryPath) {
  const std::string bytes = readBinary(libraryPath);
  std::vector<tza::Blob> blobs;
  try {
    blobs = tza::scan(bytes, libraryPath);
  } catch (const tza::TzaError& e) {
    throw ModelError(e.what());
  }
  constexpr size_t kCount = std::size(kOidnWeights);
  if (blobs.size() != kCount)
    throw ModelError(libraryPath + ": holds " + std::to_string(blobs.size()) +
                     " weight blobs, expected OIDN 2.x's " + std::to_string(kCount));
  std::vector<OidnWeights> list;
  for (size_t i = 0; i < kCount; ++i) {
    const Expected& e = kOidnWeights[i];
    OidnWeights w{e.name, {e.arch, e.in_channels, 3}, blobs[i].offset, blobs[i].size, ""};
    std::string why;
    if (!matchesNetwork(blobs[i], w.config, why))
      throw ModelError(libraryPath + ": blob " + std::to_string(i + 1) + " at offset " +
                       std::to_string(blobs[i].offset) + " should be OIDN's '" + e.name +
                       "' but has " + why);
    w.sha256 = sha256Hex(bytes.substr(blobs[i].offset, blobs[i].size));
    list.push_back(w);
  }
  return list;
}

std::string findOidnLibrary() {
  const char* command =
      "python3 -c \"import os, pyoidn; print(os.path.dirname(pyoidn.__file__))\" 2>/dev/null";
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(command, "r"), pclose);
  std::array<char, 4096> line{};
  std::string dir;
  if (pipe && fgets(line.data(), line.size(), pipe.get())) dir = line.data();
  while (!dir.empty() && (dir.back() == '\n' || dir.back() == '\r')) dir.pop_back();
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!dir.empty())
    for (const auto& entry : fs::directory_iterator(fs::path(dir) / "oidn" / "lib", ec))
      if (entry.path().filename().string().rfind("libOpenImageDenoise_core.so", 0) == 0)
        return entry.path().string();
  throw ModelError(
      "cannot find libOpenImageDenoise_core in an installed pyoidn (python3 -m pip install "
      "pyoidn, or give --lib PATH)");
}

OidnImport importOidn(const std::string& libraryPath, OidnArch arch) {
  const auto weights = listOidnWeights(libraryPath);
  const std::string bytes = readBinary(libraryPath);
  // OIDN's blob for each of our input sets at this size.
  std::vector<std::pair<std::string, std::string>> sets;
  if (arch == OidnArch::Large)
    sets = {{"hdr_alb_nrm", "hdr_calb_cnrm_large"}};
  else {
    const std::string suffix = arch == OidnArch::Small ? "_small" : "";
    for (const char* set : {"hdr", "hdr_alb", "hdr_alb_nrm"}) sets.push_back({set, set + suffix});
    // OIDN's prefilter mode at its default quality (it has no small albedo and
    // normal networks, and the large colour network is what makes it pay).
    if (arch == OidnArch::Default)
      for (const char* set : {"hdr_calb_cnrm_large", "alb", "nrm"}) sets.push_back({set, set});
  }
  OidnImport out;
  out.info.base_kind = BaseKind::Oidn;
  out.info.has_control = false;
  out.info.objective = Objective::Regression;
  out.info.oidn.arch = arch;
  out.info.oidn.input_sets.clear();
  for (const auto& set : sets) out.info.oidn.input_sets.push_back(set.first);
  out.info.input_buffers = {"albedo", "normal"};
  out.base = OidnBase(arch, out.info.oidn.input_sets);
  auto& notes = out.info.notes;
  notes["source"] = "Intel Open Image Denoise (Apache-2.0), " +
                    std::filesystem::path(libraryPath).filename().string();
  notes["source_version"] = libraryVersion(libraryPath);
  notes["source_sha256"] = sha256Hex(bytes);
  for (const auto& [set, oidnName] : sets) {
    const auto it = std::find_if(weights.begin(), weights.end(),
                                 [&](const OidnWeights& w) { return w.name == oidnName; });
    OidnUNet net = out.base->net(set);
    copyWeights(tza::parse(bytes, it->offset, libraryPath), net);
    notes[set + ".weights"] = oidnName;
    notes[set + ".blob_offset"] = std::to_string(it->offset);
    notes[set + ".blob_sha256"] = it->sha256;
  }
  out.base->eval();
  return out;
}

}  // namespace dn
