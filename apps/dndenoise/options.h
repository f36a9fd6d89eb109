// dndenoise's options: the command line parsed and checked, and which models
// each option acts on (checked once the model is loaded).
#pragma once

#include <map>
#include <string>
#include <vector>

#include "dn/infer/denoiser.h"
#include "dn/io/buffer_io.h"
#include "dn/ocio_preview.h"
#include "dn/passes/sequence_passes.h"
#include "dn/temporal/sequence.h"

namespace dn::dndenoise {

// Which models an option acts on (checked once the model is loaded).
enum class OptionScope {
  OidnBase,          // models over OIDN's networks (the default)
  Control,           // those with a Control Module
  DiffusionControl,  // those with a diffusion Control Module
  Diffusion,         // a diffusion Control Module or the from-scratch model
  Scratch,           // the from-scratch diffusion model (an experiment)
};

struct GivenOption {
  std::string flag;
  OptionScope scope;
};

struct Options {
  std::vector<std::string> inputs;
  std::map<std::string, std::string> separateFiles;  // buffer -> file
  ReadOptions read;
  std::vector<std::string> buffers;  // --buffers: the only buffers to use
  std::string output, model, layer = "Denoised", reference, maxErrorMetric = "l1", device = "cpu";
  std::string frames;
  double maxError = -1.0;
  bool rgbOnly = false, floatOut = false, inplace = false, verbose = false, skipMissing = false;
  int repeats = 1;
  DenoiseOptions denoise;
  std::string preview;
  tonemap::PreviewOptions display;
  bool listViews = false;
  bool passes = false;                                    // --passes
  PassesOverTime passesOverTime = PassesOverTime::Light;  // --passes-temporal
  bool passesTemporalGiven = false;
  std::vector<GivenOption> given;           // options that act on some models only
  bool temporal = true;                     // --temporal on|filter; off: false
  dn::temporal::SequenceSettings sequence;  // --window, --motion, --temporal filter
  std::string temporalTrust = "rules";      // --temporal-trust learned|rules
  std::string temporalFilter = "auto";      // --temporal-filter auto|cpu|tensors

  bool wasGiven(const std::string& flag) const;  // whether `given` has `flag`
};

// The options of the command line; -h, --version and --list-views print and exit.
Options parseArgs(int argc, char** argv);

// One line, exit 1, for an option given that the loaded model has no use for.
void checkOptionsApply(const Options& o, const Denoiser& denoiser);

}  // namespace dn::dndenoise
