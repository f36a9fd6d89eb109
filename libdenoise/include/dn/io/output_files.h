// Process-wide facts about the files a tool writes: the provenance attributes
// every image carries, and the temporary files a signal must not leave behind.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace dn {

// Attributes every image file this process writes carries (EXR, TIFF, PNG
// metadata), e.g. {"Software", "dndenoise 0.1.0"}. "ImageHistory" is appended
// to the input's history rather than replacing it, as oiiotool does.
using Attributes = std::vector<std::pair<std::string, std::string>>;
void setProvenance(Attributes attributes);
const Attributes& provenance();

// writeImage/writeResult register their temporary file while it exists, so
// that a signal handler can remove it.
void trackTemporaryFile(const std::string& path);
void untrackTemporaryFile(const std::string& path);

// On SIGINT/SIGTERM: remove the tracked temporary files, print one line and
// exit with 128 + the signal number. Finished outputs are kept.
void removeTemporaryFilesOnSignal(const char* tool);

}  // namespace dn
