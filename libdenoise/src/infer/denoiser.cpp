#include "dn/infer/denoiser.h"

#include <cstdio>
#include <stdexcept>
#include <utility>

#include "dn/infer/oidn_pipeline.h"
#include "dn/infer/scratch_diffusion.h"

namespace dn {

namespace {

std::shared_ptr<const Pipeline> pipelineFor(const LoadedModel& model) {
  if (model.info.base_kind == BaseKind::Oidn)
    return std::make_shared<OidnPipeline>(model.info, model.oidn, model.oidnControlled);
  return std::make_shared<ScratchDiffusionPipeline>(model.info, model.model);
}

}  // namespace

std::optional<Quality> qualityFromName(const std::string& name) {
  if (name == "fast") return Quality::Fast;
  if (name == "balanced") return Quality::Balanced;
  if (name == "high") return Quality::High;
  return std::nullopt;
}

std::optional<Precision> precisionFromName(const std::string& name) {
  for (Precision p : {Precision::Float, Precision::BFloat16, Precision::Float16})
    if (name == precisionName(p)) return p;
  return std::nullopt;
}

const char* precisionName(Precision precision) {
  switch (precision) {
    case Precision::BFloat16:
      return "bf16";
    case Precision::Float16:
      return "fp16";
    default:
      return "float";
  }
}

void setQuality(DenoiseOptions& options, Quality quality) {
  options.prefilter = quality != Quality::Fast;
  options.lightPaths = quality == Quality::High;
}

void checkExposure(double requested, double automatic) {
  if (requested <= 0) return;
  const double ratio = requested / automatic;
  const double slack = 1 + 1e-6;  // the autoexposure is a float
  if (ratio * slack >= 1.0 / kMaxExposureRatio && ratio <= kMaxExposureRatio * slack) return;
  char text[200];
  std::snprintf(text, sizeof text,
                "exposure %.3g is %.3g times the frame's autoexposure (%.3g); the networks "
                "handle %g to %g times it",
                requested, ratio, automatic, 1.0 / kMaxExposureRatio, kMaxExposureRatio);
  throw std::invalid_argument(text);
}

Denoiser::Denoiser(LoadedModel model) : model_(std::move(model)), pipeline_(pipelineFor(model_)) {}

Denoiser Denoiser::fromFile(const std::string& path) { return Denoiser(loadModelFile(path)); }

std::vector<std::string> Denoiser::missingBuffers(const std::vector<std::string>& available) const {
  return pipeline_->missingBuffers(available);
}

std::vector<std::string> Denoiser::usableBuffers(const std::vector<std::string>& available) const {
  return pipeline_->usableBuffers(available);
}

std::vector<std::string> Denoiser::buffersToRead(const std::vector<std::string>& available,
                                                 const DenoiseOptions& options) const {
  return pipeline_->buffersToRead(available, options);
}

bool Denoiser::controlApplies(const std::vector<std::string>& available) const {
  const auto* oidn = dynamic_cast<const OidnPipeline*>(pipeline_.get());
  return oidn && oidn->controlApplies(available);
}

DenoiseResult Denoiser::denoise(const FrameBuffers& frame, const DenoiseOptions& options) const {
  const auto missing = missingBuffers(frame.names());
  if (!missing.empty()) {
    std::string list;
    for (const auto& m : missing) list += (list.empty() ? "" : ", ") + m;
    throw std::invalid_argument("model needs buffers the input lacks: " + list);
  }
  if (options.samples < 1) throw std::invalid_argument("samples must be at least 1");
  return pipeline_->denoise(frame, options);
}

double Denoiser::measureNoise(const FrameBuffers& frame, double exposure) const {
  return measureModelNoise(info(), frame, exposure);
}

}  // namespace dn
