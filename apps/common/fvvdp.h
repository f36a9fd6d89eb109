// FovVideoVDP (Mantiuk et al. 2021, the `pyfvvdp` package), for measuring
// only: dnmetrics itself stays free of Python and runs it in a subprocess,
// and only when asked to.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "dn/image.h"

namespace dn::cli {

struct FvvdpSettings {
  std::string python = "python3";       // an interpreter that has pyfvvdp
  std::string display = "standard_4k";  // pyfvvdp's display model
  double fps = 0;                       // > 0: the pairs are the frames of one video
};

// Collects (reference, test) pairs as a display shows them (the Reinhard
// curve, then sRGB, as FLIP sees them) in a temporary folder, then scores
// them in JOD, higher is better (10: no visible difference): each pair as an
// image, or with fps > 0 all of them as one video, flicker included.
class FvvdpScorer {
 public:
  explicit FvvdpScorer(FvvdpSettings settings);
  ~FvvdpScorer();
  FvvdpScorer(const FvvdpScorer&) = delete;
  FvvdpScorer& operator=(const FvvdpScorer&) = delete;

  void add(const Image& reference, const Image& test);
  // One score per pair, or one for the video. Throws std::runtime_error with
  // one line when the interpreter or pyfvvdp fails.
  std::vector<double> score() const;

 private:
  FvvdpSettings settings_;
  std::filesystem::path folder_;
  int pairs_ = 0;
};

}  // namespace dn::cli
