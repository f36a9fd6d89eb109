#!/usr/bin/env bash
# The CUDA path's first run, made for the lent GPU machine: the PyTorch wheel
# (CUDA LibTorch inside), nvcc, CMake and ninja, but no OpenImageIO, OpenEXR or
# network. From the repository root, after bench/gpu/prepare_carry.sh ran on
# the development machine and bench/gpu/carry travelled with the command:
#
#   bash bench/gpu/check_cuda.sh            # logs and the summary into $OUT
#
# 1. configures the inference core alone (DN_WITH_OIIO=OFF) against the wheel's
#    LibTorch and builds denoise_npy_bench, test_device and test_npy;
# 2. runs test_device (CUDA against the CPU on a small frame) and test_npy;
# 3. tiles the shipped example to 1080p and 4K (bench/gpu/make_inputs.py);
# 4. runs the base, the prefilter mode, the light-path split and the Control
#    Module on the CPU once at 1080p (the reference), then on CUDA as shipped
#    (the median of 5, the agreement in dB, and one run each traced by Kineto,
#    summed up in traces.txt), with TF32 off (the float agreement, >= 60 dB
#    wanted), with cuDNN's benchmark mode, and in bfloat16;
# 5. times 4K on CUDA in the default's tiles and in the fewest, and OIDN
#    2.5.1's own CUDA device (bench/gpu/oidn_bench.py, its usual call and its
#    prefilter recipe) at both sizes where carry/oidn exists.
# With bench/gpu/carry/build (prepare_carry.sh --cuda-build DIR: binaries built
# on the development machine against the same PyTorch wheel) step 1 is skipped:
# minutes of GPU time saved.
# Knobs: DN_GPU_REPEATS (5), DN_GPU_SIZES (1920x1080,3840x2160),
# DN_GPU_MODES_LARGE (base,prefilter,split), DN_GPU_JOBS (nproc), DN_GPU_WORK (/tmp/dn-gpu),
# DN_OIDN_LIB (bench/gpu/carry/oidn; e.g. a folder an earlier call left in /tmp).
set -uo pipefail
cd "$(dirname "$0")/../.."
out=${OUT:-/tmp/dn-gpu-out}
work=${DN_GPU_WORK:-/tmp/dn-gpu}
repeats=${DN_GPU_REPEATS:-5}
sizes=${DN_GPU_SIZES:-1920x1080,3840x2160}
jobs=${DN_GPU_JOBS:-$(nproc)}
carry=bench/gpu/carry
build=$work/build
mkdir -p "$out" "$work"
failures=()
step() { echo; echo "== $* ($(date +%T))"; }
fail() { echo "check_cuda: FAILED: $*" >&2; failures+=("$*"); }

step "machine"
command -v nvcc >/dev/null || export PATH=/usr/local/cuda/bin:$PATH
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || fail "nvidia-smi"
python3 -c 'import torch; print("torch", torch.__version__, "CUDA", torch.version.cuda,
  "available", torch.cuda.is_available(), torch.cuda.get_device_name(0) if torch.cuda.is_available() else "")' ||
  { echo "check_cuda: python3 has no torch: nothing to build against" >&2; exit 1; }
for tool in cmake ninja c++ nvcc; do
  command -v "$tool" >/dev/null || { echo "check_cuda: $tool not found" >&2; exit 1; }
done
cmake --version | head -1; c++ --version | head -1; nvcc --version | tail -1; echo "$(nproc) cores"

torch_root=$(python3 -c 'import os, torch; print(os.path.dirname(torch.__file__))')
torch_version=$(python3 -c 'import torch; print(torch.__version__)')
if [ -x "$carry/build/bin/denoise_npy_bench" ] && [ "$(cat "$carry/build/torch_version")" != "$torch_version" ]; then
  echo "check_cuda: $carry/build was built against torch $(cat "$carry/build/torch_version"), this is $torch_version: building here" >&2
  rm -rf "$carry/build"
fi
if [ -x "$carry/build/bin/denoise_npy_bench" ]; then
  step "prebuilt: $carry/build (built elsewhere against torch $torch_version)"
  build=$carry/build
  export LD_LIBRARY_PATH="$torch_root/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
  # The tests find the model and fixtures under the source folder they were built in.
  source_dir=$(cat "$build/source_dir")
  [ -e "$source_dir" ] || { mkdir -p "$(dirname "$source_dir")" && ln -s "$PWD" "$source_dir"; }
  tests=$([ -x "$build/bin/test_device" ] && echo ON || echo OFF)
else
  step "configure: the inference core alone against the wheel's LibTorch"
  prefixes="$torch_root/share/cmake;$torch_root"  # the root too: its lib/ before any system libtorch
  tests=ON
  if [ -d "$carry/doctest" ]; then
    prefixes="$prefixes;$PWD/$carry/doctest"
  elif ! find /usr -name doctestConfig.cmake -print -quit 2>/dev/null | grep -q .; then
    echo "check_cuda: no doctest (run prepare_carry.sh and carry $carry): building without the tests" >&2
    tests=OFF
  fi
  start=$(date +%s)
  cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DDN_WITH_OIIO=OFF -DDN_BUILD_TESTS=$tests \
    -DCMAKE_PREFIX_PATH="$prefixes" >"$out/build.log" 2>&1 || { tail -40 "$out/build.log"; exit 1; }
  echo "configured in $(($(date +%s) - start)) s"

  step "build"
  start=$(date +%s)
  targets=(denoise_npy_bench)
  [ "$tests" = ON ] && targets+=(test_device test_npy)
  cmake --build "$build" -j"$jobs" --target "${targets[@]}" >>"$out/build.log" 2>&1 ||
    { grep -E "error|undefined" "$out/build.log" | head -30; exit 1; }
  echo "built ${targets[*]} in $(($(date +%s) - start)) s with $jobs jobs"
  grep -c "warning:" "$out/build.log" | xargs echo "compiler warnings:"
fi

if [ "$tests" = ON ]; then
  step "tests: device placement (CUDA against the CPU) and .npy"
  for t in test_device test_npy; do
    "$build/bin/$t" -s >>"$out/tests.log" 2>&1 || fail "$t (see tests.log)"
  done
  grep -E "CUDA|dB|Status|test cases" "$out/tests.log" | head -20
fi

step "inputs: the shipped example tiled to $sizes"
python3 bench/gpu/make_inputs.py --example "$carry/example.npz" --out "$work/inputs" --sizes "$sizes" ||
  { echo "check_cuda: no inputs" >&2; exit 1; }

bench() { "$build/bin/denoise_npy_bench" --model models/default.dnm "$@" 2>&1 | tee -a "$out/bench.log"; }
first=${sizes%%,*}
in1=$work/inputs/$first
step "CPU reference at $first (one run each)"
bench --input "$in1" --devices cpu --repeats 1 --warmup 0 --output "$work/ref-$first" ||
  fail "CPU reference $first"
step "CUDA at $first as shipped (TF32 on, LibTorch's default): times and agreement"
bench --input "$in1" --devices cuda --repeats "$repeats" --warmup 1 --reference "$work/ref-$first" ||
  fail "CUDA $first"
step "CUDA at $first: one run of each mode traced by Kineto (traces.txt)"
"$build/bin/denoise_npy_bench" --model models/default.dnm --input "$in1" --devices cuda --repeats 1 \
  --warmup 1 --trace "$work/trace" >/dev/null 2>"$out/trace.err" || fail "trace (see trace.err)"
for trace in "$work"/trace/*.json; do
  python3 bench/gpu/trace_summary.py "$trace" >>"$out/traces.txt" 2>&1 || fail "trace summary $trace"
  echo >>"$out/traces.txt"
done
grep -E "traced|outside" "$out/traces.txt"
gzip -c "$work/trace/prefilter_cuda.json" >"$out/prefilter_cuda.json.gz" 2>/dev/null
step "CUDA at $first, TF32 off: agreement with the CPU in float (>= 60 dB)"
bench --input "$in1" --devices cuda --repeats 1 --warmup 1 --tf32 off --reference "$work/ref-$first" ||
  fail "CUDA $first TF32 off"
step "CUDA at $first with cuDNN's benchmark mode (it times the algorithms for each shape once)"
bench --input "$in1" --devices cuda --repeats "$repeats" --warmup 1 --cudnn-benchmark on \
  --reference "$work/ref-$first" || fail "CUDA $first cuDNN benchmark"
step "CUDA at $first in bfloat16 (the OIDN base's inner convolutions; OIDN's own CUDA device runs in half)"
bench --input "$in1" --devices cuda --modes base,prefilter,split --repeats "$repeats" --warmup 1 \
  --bfloat16 on --reference "$work/ref-$first" || fail "CUDA $first bfloat16"
modes_large=${DN_GPU_MODES_LARGE:-base,prefilter,split}
for size in ${sizes//,/ }; do
  [ "$size" = "$first" ] && continue
  step "CUDA at $size ($modes_large): tiles for the 3 GB default budget, then the fewest (--max-memory 64)"
  for memory in 0 64; do
    flags=(); [ $memory -gt 0 ] && flags=(--max-memory $memory)
    bench --input "$work/inputs/$size" --devices cuda --modes "$modes_large" --repeats 3 --warmup 1 \
      "${flags[@]}" || fail "CUDA $size memory $memory"
  done
done

oidn_lib=${DN_OIDN_LIB:-$carry/oidn}
if [ -f "$oidn_lib/libOpenImageDenoise.so.2" ]; then
  for size in ${sizes//,/ }; do
    step "OIDN 2.5.1 on CUDA at $size"
    LD_LIBRARY_PATH="$oidn_lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" python3 bench/gpu/oidn_bench.py --lib "$oidn_lib" --input "$work/inputs/$size" --device cuda \
      --repeats "$repeats" 2>&1 | tee -a "$out/bench.log" || fail "OIDN CUDA $size"
  done
else
  echo "check_cuda: $oidn_lib has no OIDN (prepare_carry.sh --with-oidn): no OIDN CUDA timings" >&2
fi

step "summary (median seconds; PSNR of CUDA against the CPU in dB, >= 60 wanted in float with TF32 off)"
grep '^RESULT' "$out/bench.log" | sed 's/^RESULT //' | tee "$out/summary.txt"
awk '/^RESULT.*precision=float.*tf32=off/ { for (i = 2; i <= NF; ++i) if ($i ~ /^psnr_vs_cpu=/) { split($i, kv, "=");
       if (kv[2] != "inf" && kv[2] + 0 < 60) { print "check_cuda: below 60 dB: " $0; bad = 1 } } } END { exit bad }' \
  "$out/bench.log" || fail "agreement below 60 dB"
if [ ${#failures[@]} -gt 0 ]; then
  printf 'check_cuda: %d step(s) failed: %s\n' ${#failures[@]} "${failures[*]}"
  exit 1
fi
echo "check_cuda: every step passed"
