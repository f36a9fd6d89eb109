// Converts the weights compiled into OIDN's core library (TZA blobs, see
// dn/io/tza.h) into the project's model file: the pretrained base.
//
// The blobs carry no names. OIDN 2.x builds them in alphabetical order of
// their weight names (alb, alb_large, hdr, hdr_small, hdr_alb, ...), so a
// library whose blobs have exactly the expected shapes in that order is
// identified blob by blob; anything else is refused. That the HDR blobs are
// the HDR filters is checked against OIDN's own output (tests/test_oidn_base.cpp).
#pragma once

#include <string>
#include <vector>

#include "dn/nn/model_file.h"
#include "dn/nn/oidn_unet.h"

namespace dn {

// One of OIDN's weight blobs as found in its library.
struct OidnWeights {
  std::string name;  // OIDN's name, e.g. "hdr_alb_nrm", "hdr_calb_cnrm_large"
  OidnUNetConfig config;
  uint64_t offset = 0, size = 0;
  std::string sha256;
};

// Names every blob of `libraryPath` (throws ModelError naming the file when it
// is unreadable or its blobs are not OIDN 2.x's set).
std::vector<OidnWeights> listOidnWeights(const std::string& libraryPath);

// libOpenImageDenoise_core of the installed pyoidn package (asks python3 where
// it is); throws ModelError when it cannot be found.
std::string findOidnLibrary();

struct OidnImport {
  ModelInfo info;
  OidnBase base{nullptr};
};

// The base of size `arch` with one network per HDR input set (colour;
// + albedo; + albedo + normal), weights and provenance from `libraryPath`.
// OIDN ships the large size only for clean (prefiltered) albedo and normal:
// that base holds the one network, "hdr_calb_cnrm_large", as its hdr_alb_nrm.
OidnImport importOidn(const std::string& libraryPath, OidnArch arch);

}  // namespace dn
