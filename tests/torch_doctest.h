// Include this instead of <doctest/doctest.h> in tests that use LibTorch: c10's
// logging defines glog-style CHECK macros (aborting, uncounted) that would
// otherwise shadow doctest's assertions.
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
