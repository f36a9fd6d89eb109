// Include this instead of <doctest/doctest.h> in tests that use LibTorch:
// Debian's LibTorch is built with glog, whose CHECK() would replace doctest's
// (aborting instead of reporting), so torch comes first and doctest wins.
#pragma once

#include <torch/torch.h>

#undef CHECK
#undef CHECK_EQ
#undef CHECK_NE
#undef CHECK_LT
#undef CHECK_LE
#undef CHECK_GT
#undef CHECK_GE
#include <doctest/doctest.h>
