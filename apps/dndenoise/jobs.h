// What dndenoise will do, planned and checked before the model loads: the
// (input, output) jobs, the --preview pictures, the display transform, the
// files, and the temporal plan of a sequence.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "dn/ocio_preview.h"
#include "dn/temporal/sequence.h"
#include "dndenoise/options.h"

namespace dn::dndenoise {

// (input, output) pairs; the input is empty for separate buffer files.
using Jobs = std::vector<std::pair<std::string, std::string>>;

// (input, output) pairs from files, patterns or a folder output.
Jobs planJobs(const Options& o);

// Where each job's --preview picture goes (none without --preview).
std::vector<std::string> planPreviews(const Options& o, const Jobs& jobs);

// The display transform, when some picture needs it.
std::optional<tonemap::OcioDisplay> displayFor(const Options& o, const Jobs& jobs);

// Every check that needs no denoising, before the first frame.
void checkFilesBeforeWork(const Options& o, const Jobs& jobs,
                          const std::vector<std::string>& previews);

// The temporal plan of a sequence input (--temporal on, one input pattern with
// motion vectors), or nullptr; prints one line when it denoises frame by frame.
std::unique_ptr<temporal::Sequence> planSequence(const Options& o, const Jobs& jobs,
                                                 const Denoiser& denoiser);

}  // namespace dn::dndenoise
