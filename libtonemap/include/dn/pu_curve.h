// The constants of OIDN's PU transfer function (dn::tonemap::pu), for code
// that evaluates the curve elsewhere than libtonemap's scalar functions, such
// as on a GPU with tensor operations (dn/infer/oidn_filter.cpp).
#pragma once

namespace dn::tonemap::pu_curve {

// The curve's pieces: a * y below y0, b * y^c + d below y1, e * log(y + f) + g
// above; x0 and x1 are the encoded values at y0 and y1. The curve is divided
// by its value at half's largest value, 65504, which then maps to 1.
constexpr float kA = 1.41283765e+03f, kB = 1.64593172e+00f, kC = 4.31384981e-01f,
                kD = -2.94139609e-03f, kE = 1.92653254e-01f, kF = 6.26026094e-03f,
                kG = 9.98620152e-01f, kY0 = 1.57945760e-06f, kY1 = 3.22087631e-02f,
                kX0 = 2.23151711e-03f, kX1 = 3.70974749e-01f;
constexpr float kHalfMax = 65504.0f;

}  // namespace dn::tonemap::pu_curve
