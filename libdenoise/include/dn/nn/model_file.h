// Model files: a checksummed container holding key=value metadata (format
// version, network configs, input buffers, tonemap curve, prediction type,
// schedule) and a LibTorch archive of the weights. Every failure to read one is
// a dn::ModelError with a one-line message naming the file.
#pragma once

#include <cstdint>
#include <functional>
#include <iosfwd>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "dn/diffusion/schedule.h"
#include "dn/nn/control_module.h"
#include "dn/nn/oidn_control.h"
#include "dn/nn/oidn_unet.h"
#include "dn/nn/prior.h"
#include "dn/nn/unet.h"

namespace dn {

class ModelError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

constexpr int kModelFormatVersion = 1;

// Diffusion: the iterative sampler of the paper. Regression: the same networks
// trained with L1 to map the noisy render to the clean image in one pass (the
// ablation that tells whether diffusion earns its cost).
enum class Objective { Diffusion, Regression };

// What a model file's network is: the project's diffusion UNet with its
// Control Module, or OIDN's pretrained UNets (one per input set), run once.
enum class BaseKind { DiffusionUNet, Oidn };

struct OidnBaseInfo {
  OidnArch arch = OidnArch::Default;
  std::vector<std::string> input_sets = {"hdr_alb_nrm"};
  // With ModelInfo::has_control: the Control Module steering one of the nets,
  // and for diffusion models the default noise levels of the refinement.
  OidnControlConfig control;
  std::vector<double> sigmas;
};

struct ModelInfo {
  BaseKind base_kind = BaseKind::DiffusionUNet;
  OidnBaseInfo oidn;        // base_kind == Oidn
  UNetConfig base;          // base_kind == DiffusionUNet
  bool has_control = true;  // false: the base prior alone (pretraining, ablations)
  ControlConfig control;
  std::vector<std::string> input_buffers;  // canonical buffer names feeding aux, in order
  std::string tonemap = "log";             // curve name of dn::tonemap (radiance -> model range)
  Objective objective = Objective::Diffusion;
  Prediction prediction = Prediction::Epsilon;
  ScheduleKind schedule = ScheduleKind::Cosine;
  int64_t schedule_steps = 1000;
  std::string respacing = "super27";         // default inference respacing
  std::map<std::string, std::string> notes;  // free-form (training data, steps, ...)

  NoiseSchedule trainingSchedule() const { return makeSchedule(schedule, schedule_steps); }
  NoiseSchedule samplingSchedule() const { return respace(trainingSchedule(), respacing); }
};

// Comma-separated lists in model metadata ("1,2,4", "albedo,normal"); empty items are dropped.
std::string joinInts(const std::vector<int64_t>& values);
std::string joinStrings(const std::vector<std::string>& values);
std::vector<std::string> splitList(const std::string& text);

std::string modelInfoToText(const ModelInfo& info);
// `source` names the file in error messages; throws ModelError.
ModelInfo modelInfoFromText(const std::string& text, const std::string& source);

// A denoiser with fresh weights for `info` (throws std::invalid_argument on a
// bad config, or when `info` is not a diffusion model).
std::shared_ptr<ConditionalDenoiser> buildDenoiser(const ModelInfo& info);

struct LoadedModel {
  ModelInfo info;
  std::shared_ptr<ConditionalDenoiser> model;  // base_kind == DiffusionUNet
  OidnBase oidn{nullptr};                      // base_kind == Oidn
  OidnControlled oidnControlled{nullptr};      // base_kind == Oidn with has_control
  // The base prior inside `model` (to freeze under a new Control Module).
  std::shared_ptr<DenoisingPrior> prior() const;
};

// Atomic: writes a temporary file next to `path`, then renames it.
void saveModelFile(const std::string& path, const ModelInfo& info, const torch::nn::Module& model);
LoadedModel loadModelFile(const std::string& path);

// The container under model files and training checkpoints: `kind` tags what it
// holds, `text` is metadata, `archive` the tensors. Written atomically.
// `write` into a temporary file beside `path`, renamed into place when
// complete: no partial output. Throws ModelError naming `path`.
void writeAtomically(const std::string& path, const std::function<void(std::ostream&)>& write);

void writeArchiveFile(const std::string& path, const std::string& kind, const std::string& text,
                      torch::serialize::OutputArchive& archive);
struct ArchiveFile {
  int version = 0;
  std::string text;
  torch::serialize::InputArchive archive;
};
ArchiveFile readArchiveFile(const std::string& path, const std::string& kind);
// The kind a container file holds ("model", "kernel-model", ...) from its header
// alone; throws ModelError when the file is not such a container.
std::string archiveKind(const std::string& path);

// Loads `module`'s parameters and buffers from `archive`, checking every shape
// against the module's own; throws ModelError naming `source` on any mismatch.
void loadModuleWeights(torch::nn::Module& module, torch::serialize::InputArchive& archive,
                       const std::string& source);

}  // namespace dn
