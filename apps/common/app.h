// What every dn* tool does the same way: --version, provenance in the files it
// writes, the default model's place, and the rule that no output overwrites an
// input of the same command.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace dn::cli {

// "dndenoise 0.1.0 (git v0.1-12-gabc1234)" and one line per linked library.
using Components = std::vector<std::pair<std::string, std::string>>;
std::string versionText(const std::string& tool, const Components& libraries);
// The libraries every tool links (OpenImageIO, OpenEXR through it, fmt).
Components commonComponents();

// The command line, quoted so it can be pasted back into a shell.
std::string commandLine(int argc, char** argv);

// Software, ImageHistory and dn:* attributes for every image the process
// writes; `model` may be empty (dnmetrics). Reads the model to checksum it
// unless given its sha256.
void setToolProvenance(const std::string& tool, int argc, char** argv,
                       const std::string& model = "", std::string modelSha256 = "");

// $DN_MODEL, else default.dnm in $DN_MODEL_DIR, beside the build tree's
// executables (<exe dir>/../models) or in the install tree
// (<exe dir>/../share/<project>/models). Throws an IoError naming the places
// looked in when none holds it.
std::string defaultModelPath();

// One output of a command, and what it is written from (for messages).
struct Output {
  std::string path, from;
};

// Before any work: every input readable; no output resolving (after symlinks
// and hard links) to an input, or to another output; every output's folder
// present and writable. Allow lets an output replace its own `from` (dndenoise
// --inplace); Offer names that option in the refusal.
enum class Inplace { No, Offer, Allow };
void checkFiles(const std::vector<std::string>& inputs, const std::vector<Output>& outputs,
                Inplace inplace = Inplace::No);
void checkReadable(const std::string& path);

}  // namespace dn::cli
