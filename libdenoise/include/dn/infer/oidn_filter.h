// The pretrained base run as OIDN runs it on HDR colour (+ albedo + normal):
// the colour scaled by OIDN's autoexposure and encoded with its PU transfer
// function, albedo clamped to [0, 1], normals clamped to [-1, 1] and mapped to
// [0, 1], NaN as 0; the frame zero-padded to a multiple of 16; the output
// clamped at 0, decoded and scaled back. Large frames run in overlapping tiles.
// The albedo network (set "alb") works in sRGB and the normal network ("nrm")
// on the mapped normals, both unexposed, as OIDN denoises auxiliary images.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "dn/infer/frame_uploads.h"
#include "dn/infer/tiler.h"
#include "dn/io/buffers.h"
#include "dn/nn/oidn_unet.h"

namespace dn {

// OIDN's tile overlap for its default and small networks (receptive field 174
// px: half of it, rounded up to the alignment), and for the large one (202 px).
constexpr int64_t kOidnOverlap = 96;
constexpr int64_t kOidnOverlapLarge = 112;
// OIDN splits frames above 2160x2160 pixels into tiles even without a memory bound.
constexpr int64_t kOidnMaxTilePixels = 2160 * 2160;

// (1, 3 * buffers, h, w) network input for a region of `frame`, with the
// colour multiplied by `exposure`, on the CPU.
torch::Tensor oidnInput(const FrameBuffers& frame, const OidnInputSet& set, float exposure,
                        const TileRect& region);
// Buffers already on the run's device, by name: (3, H, W) over the whole
// frame in the frame's units, taken instead of the frame's images.
using DeviceBuffers = std::map<std::string, torch::Tensor>;
// A buffer of the frame on `device` as DeviceBuffers holds it: its stored
// channels cross as stored floats (dn::imageToDevice), and a
// single channel is broadcast there.
torch::Tensor bufferOnDevice(const Image& image, torch::Device device);
// The same from a buffer already there as stored, (1, C, H, W).
torch::Tensor bufferOnDevice(const torch::Tensor& stored);
// The same made on `device` with tensor operations from the buffers as
// stored: what crosses to a GPU is the region's raw pixels, or nothing for
// the buffers in `onDevice`. Agrees with oidnInput to float rounding of the
// curves (test_oidn_base). `exposure` may be a 0-dim float tensor on `device`.
torch::Tensor oidnInputOnDevice(const FrameBuffers& frame, const OidnInputSet& set, float exposure,
                                const TileRect& region, torch::Device device,
                                const DeviceBuffers& onDevice = {});
torch::Tensor oidnInputOnDevice(const FrameBuffers& frame, const OidnInputSet& set,
                                const torch::Tensor& exposure, const TileRect& region,
                                torch::Device device, const DeviceBuffers& onDevice = {});
// Network output (1, 3, h, w) -> the set's denoised buffer in the frame's
// units: linear HDR radiance, albedo in [0, 1] or normals in [-1, 1]. A CPU
// output is decoded on the CPU, any other where it is
// (oidnOutputDecodeOnDevice, which takes any device).
torch::Tensor oidnOutputDecode(const torch::Tensor& output, const OidnInputSet& set,
                               float exposure);
torch::Tensor oidnOutputDecodeOnDevice(const torch::Tensor& output, const OidnInputSet& set,
                                       float exposure);
torch::Tensor oidnOutputDecodeOnDevice(const torch::Tensor& output, const OidnInputSet& set,
                                       const torch::Tensor& exposure);
// OIDN's PU transfer function (tonemap::pu) in tensor operations on any
// device, on values already made finite and clamped at 0.
torch::Tensor puEncodeTensor(const torch::Tensor& radiance);
// OIDN's autoexposure (tonemap::oidnExposure) of a colour (C, H, W) or
// (1, C, H, W) where it is, as a 0-dim float tensor there: the bins' sums in
// double, so it agrees with the CPU's to float rounding, and no value has to
// come back to the host before the networks run.
torch::Tensor oidnExposureOnDevice(const torch::Tensor& color);

struct OidnRunOptions {
  float exposure = 0.0f;          // 0: OIDN's autoexposure
  int64_t tile = 0;               // 0: the whole frame up to maxTilePixels, or
  double maxMemoryBytes = 3.0e9;  //    the largest tile under this budget
  // OIDN's CPU tiling; 0: no cap (a GPU's memory budget alone decides).
  int64_t maxTilePixels = kOidnMaxTilePixels;
  torch::Device device = torch::kCPU;
  std::function<void(double)> progress;  // 0..1 after every tile
  // Replaces `net` on each tile: the padded input (1, C, h, w) and the tile's
  // region of the frame -> the network's output of the same size.
  std::function<torch::Tensor(const torch::Tensor&, const TileRect&)> network;
  // Off the CPU: inputs a previous network left on the device (oidnInputOnDevice).
  DeviceBuffers onDevice;
  // Off the CPU, where given: the frame's buffers as sent once for all its
  // runs and the gate. A run on another frame (one made from it) sends its own.
  FrameUploads* uploads = nullptr;
  // Off the CPU under autoexposure runOidn reads the exposure back at its end,
  // a wait for the device; with this set it leaves that to the caller
  // (OidnRunResult::exposureOnDevice), who can queue more work first.
  bool deferExposureRead = false;
};

struct OidnRunResult {
  torch::Tensor image;             // (1, 3, H, W) on the run's device: the set's denoised buffer
  float exposure = 1.0f;           // 0 where the read was deferred (deferExposureRead)
  torch::Tensor exposureOnDevice;  // the same as a 0-dim tensor there (off the CPU)
  int64_t tileSize = 0;
  std::size_t tileCount = 0;
};

// Denoises `frame` (its colour, or for "alb" and "nrm" its albedo or normal)
// with `net`, whose inputs are `set`'s buffers.
OidnRunResult runOidn(OidnUNet& net, const OidnInputSet& set, const FrameBuffers& frame,
                      const OidnRunOptions& options);

// Activation bytes per pixel of one forward pass of `config`, for tiling.
double oidnBytesPerPixel(const OidnUNetConfig& config);

// The tiles runOidn runs a frame of height x width in: options.tile, else the
// whole frame where it fits maxMemoryBytes (and maxTilePixels), else the
// layout that runs the networks over the fewest pixels. `blend`: the overlap.
Tiler planOidnTiles(int64_t height, int64_t width, double bytesPerPixel, int64_t blend,
                    const OidnRunOptions& options);

// The share of a GPU's free memory the networks' activations may take: the
// rest holds the frame's buffers there, cuDNN's workspaces (its benchmark
// mode tries algorithms that need more) and what other processes allocate.
constexpr double kDeviceBudgetShare = 0.5;
double deviceMemoryBudget(double freeBytes);

}  // namespace dn
