#!/usr/bin/env bash
# The GPU check, made for the lent GPU machine: the PyTorch wheel (CUDA
# LibTorch inside), nvcc, CMake and ninja, but no OpenImageIO, OpenEXR or
# network. From the repository root, after bench/gpu/prepare_carry.sh ran on
# the development machine and bench/gpu/carry travelled with the command:
#
#   bash bench/gpu/check_cuda.sh          # everything but OIDN (the model travels)
#   bash bench/gpu/check_cuda.sh --oidn   # then OIDN 2.5.1 on the same warm machine
#                                         # (its libraries travel, the model does not)
#
# 1. uses the binaries in carry/build (built on the development machine against
#    the same wheel) or configures the inference core alone (DN_WITH_OIIO=OFF)
#    and builds it;
# 2. runs test_device (CUDA against the CPU, float and half), test_npy, test_tiler,
#    test_temporal_device (the temporal filter's tensor path against its CPU path,
#    on the CPU device and on CUDA);
# 3. tiles the shipped example to each size (bench/gpu/make_inputs.py);
# 4. at the first size: every mode on the CPU once (the reference), then on
#    the device in float with TF32 off (the agreement, >= 60 dB or the check
#    fails), as shipped (float, TF32 on, cuDNN's benchmark mode on), in half
#    (fp16: its agreement in dB), in bfloat16, with the benchmark mode off, and
#    one run of three modes traced by Kineto (traces.txt);
# 5. at the other sizes: the modes in float and half with the budget from the
#    GPU's free memory (one tile), and the prefilter mode in the old 3 GB tiles;
# 6. the temporal default per frame against frame by frame at the first size
#    (bench/temporal_npy_bench, a synthetic shot): on CUDA the filter as tensor
#    operations there, in float and half; on the CPU its per-pixel code and the
#    tensor path; the tensor path's result against the per-pixel code's
#    (>= 100 dB or the check fails);
# 7. with --oidn (or when carry/oidn came along): OIDN 2.5.1's CUDA device at
#    every size (bench/gpu/oidn_bench.py);
# 8. writes $OUT/results/DATE-GPU.txt: the RESULT lines of every run (today's
#    key=value format) and the ratios to OIDN (bench/gpu/summarize.py). The
#    --oidn call adds its lines to the file the first call left on the machine.
#
# The same script runs end to end on the CPU, at a small size, in CI:
#   DN_GPU_DEVICE=cpu DN_GPU_SIZES=96x64 DN_GPU_BUILD=build-core bash bench/gpu/check_cuda.sh
# Knobs: DN_GPU_DEVICE (cuda), DN_GPU_SIZES (1920x1080,3840x2160),
# DN_GPU_REPEATS (5; 3 at the other sizes), DN_GPU_BUILD (a build folder to use
# as it is), DN_GPU_JOBS (nproc), DN_GPU_WORK (/tmp/dn-gpu),
# DN_GPU_TEMPORAL (radius,frames: 4,3), DN_OIDN_LIB (bench/gpu/carry/oidn).
set -uo pipefail
cd "$(dirname "$0")/../.."
oidn_only=0
[ "${1:-}" = "--oidn" ] && oidn_only=1
device=${DN_GPU_DEVICE:-cuda}
out=${OUT:-/tmp/dn-gpu-out}
work=${DN_GPU_WORK:-/tmp/dn-gpu}
repeats=${DN_GPU_REPEATS:-5}
sizes=${DN_GPU_SIZES:-1920x1080,3840x2160}
jobs=${DN_GPU_JOBS:-$(nproc)}
temporal=${DN_GPU_TEMPORAL:-4,3}
carry=bench/gpu/carry
build=$work/build
mkdir -p "$out/results" "$work"
failures=()
step() { echo; echo "== $* ($(date +%T))"; }
fail() { echo "check_cuda: FAILED: $*" >&2; failures+=("$*"); }
[ "$device" = cuda ] || [ "$device" = cpu ] ||
  { echo "check_cuda: DN_GPU_DEVICE must be cuda or cpu, got $device" >&2; exit 2; }

step "machine"
gpu=cpu
if [ "$device" = cuda ]; then
  command -v nvcc >/dev/null || export PATH=/usr/local/cuda/bin:$PATH
  nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || fail "nvidia-smi"
  gpu=$(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1 | tr -c 'A-Za-z0-9\n' '-' | sed 's/-*$//')
  gpu=${gpu:-GPU}
fi
echo "$(nproc) cores; results for $gpu"
# The results of this machine's calls, kept between them (the --oidn call adds to it).
results=$work/results.txt
[ "$oidn_only" = 1 ] || : >"$results"
record() { grep '^RESULT' "$1" | sed 's/^RESULT //' >>"$results"; }

inputs() {
  step "inputs: the shipped example tiled to $sizes"
  python3 bench/gpu/make_inputs.py --example "$carry/example.npz" --out "$work/inputs" --sizes "$sizes" ||
    { echo "check_cuda: no inputs" >&2; exit 1; }
}

oidn() {
  local lib=${DN_OIDN_LIB:-$carry/oidn}
  if [ ! -f "$lib/libOpenImageDenoise.so.2" ]; then
    echo "check_cuda: $lib has no OIDN (prepare_carry.sh --with-oidn; it travels without the model: --oidn)" >&2
    return
  fi
  for size in ${sizes//,/ }; do
    step "OIDN 2.5.1 on $device at $size"
    LD_LIBRARY_PATH="$lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" python3 bench/gpu/oidn_bench.py --lib "$lib" \
      --input "$work/inputs/$size" --device "$device" --repeats "$repeats" 2>&1 | tee "$work/oidn.log" ||
      fail "OIDN $device $size"
    record "$work/oidn.log"
  done
}

finish() {
  step "results: median seconds; PSNR against the CPU in dB (>= 60 wanted in float with TF32 off)"
  local file
  file="$out/results/$(date +%F)-$gpu.txt"
  {
    echo "# bash bench/gpu/check_cuda.sh on $gpu, $(date -u '+%F %T') UTC, $(nproc) cores, device $device"
    # The device machine's copy of .git can be older than the tree it ran:
    # prepare_carry.sh notes the commit the carry was made from.
    echo "# commit $(cat "$carry/commit" 2>/dev/null || git rev-parse --short HEAD 2>/dev/null || echo unknown), torch ${torch_version:-?}"
    cat "$results"
    python3 bench/gpu/summarize.py "$results" | sed 's/^/# /'
  } >"$file" || fail "results file"
  cat "$file"
  awk '/precision=float/ && /tf32=off/ { for (i = 1; i <= NF; ++i) if ($i ~ /^psnr_vs_cpu=/) {
         split($i, kv, "="); if (kv[2] != "inf" && kv[2] + 0 < 60) { print "check_cuda: below 60 dB: " $0; bad = 1 } } }
       END { exit bad }' "$results" || fail "agreement below 60 dB"
  awk '/mode=temporal/ { for (i = 1; i <= NF; ++i) if ($i ~ /^filter_psnr_db=/) {
         split($i, kv, "="); if (kv[2] + 0 < 100) { print "check_cuda: temporal filter below 100 dB: " $0; bad = 1 } } }
       END { exit bad }' "$results" || fail "temporal filter's agreement below 100 dB"
  if [ ${#failures[@]} -gt 0 ]; then
    printf 'check_cuda: %d step(s) failed: %s\n' ${#failures[@]} "${failures[*]}"
    exit 1
  fi
  echo "check_cuda: every step passed ($file)"
  exit 0
}

torch_version=$(python3 -c 'import torch; print(torch.__version__)' 2>/dev/null)
if [ "$oidn_only" = 1 ]; then
  [ -d "$work/inputs" ] || inputs
  oidn
  finish
fi

if [ -n "${DN_GPU_BUILD:-}" ]; then
  step "build: $DN_GPU_BUILD as it is"
  build=$DN_GPU_BUILD
  tests=$([ -x "$build/bin/test_device" ] && echo ON || echo OFF)
else
  if [ -z "$torch_version" ]; then
    echo "check_cuda: python3 has no torch: nothing to build against (or DN_GPU_BUILD=DIR)" >&2
    exit 1
  fi
  torch_root=$(python3 -c 'import os, torch; print(os.path.dirname(torch.__file__))')
  export LD_LIBRARY_PATH="$torch_root/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
  if [ -x "$carry/build/bin/denoise_npy_bench" ] && [ "$(cat "$carry/build/torch_version")" != "$torch_version" ]; then
    echo "check_cuda: $carry/build was built against torch $(cat "$carry/build/torch_version"), this is $torch_version: building here" >&2
    rm -rf "$carry/build"
  fi
  if [ -x "$carry/build/bin/temporal_npy_bench" ]; then
    step "prebuilt: $carry/build (built elsewhere against torch $torch_version)"
    build=$carry/build
    # The tests find the model and fixtures under the source folder they were built in.
    source_dir=$(cat "$build/source_dir")
    [ -e "$source_dir" ] || { mkdir -p "$(dirname "$source_dir")" && ln -s "$PWD" "$source_dir"; }
    tests=$([ -x "$build/bin/test_device" ] && echo ON || echo OFF)
  else
    step "configure and build the inference core alone against the wheel's LibTorch"
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
    targets=(denoise_npy_bench temporal_npy_bench)
    [ "$tests" = ON ] && targets+=(test_device test_npy test_tiler test_temporal_device)
    cmake --build "$build" -j"$jobs" --target "${targets[@]}" >>"$out/build.log" 2>&1 ||
      { grep -E "error|undefined" "$out/build.log" | head -30; exit 1; }
    echo "built ${targets[*]} in $(($(date +%s) - start)) s with $jobs jobs"
    grep -c "warning:" "$out/build.log" | xargs echo "compiler warnings:"
  fi
fi

if [ "$tests" = ON ]; then
  step "tests: device placement, half, the GPU path's pieces (on $device too), .npy, tiles"
  for t in test_device test_npy test_tiler test_temporal_device; do
    [ -x "$build/bin/$t" ] || continue
    "$build/bin/$t" >>"$out/tests.log" 2>&1 || fail "$t (see tests.log)"
  done
  grep -E "dB|Status|test cases" "$out/tests.log" | head -60
fi

inputs
bench() {
  "$build/bin/denoise_npy_bench" --model models/default.dnm "$@" 2>&1 | tee "$work/bench.log"
  local rc=${PIPESTATUS[0]}
  cat "$work/bench.log" >>"$out/bench.log"
  record "$work/bench.log"
  return "$rc"
}
first=${sizes%%,*}
in1=$work/inputs/$first
ref=$work/ref-$first
modes=base,prefilter,split,control,default
step "CPU reference at $first (one run of each mode)"
bench --input "$in1" --modes "$modes" --devices cpu --repeats 1 --warmup 0 --output "$ref" ||
  fail "CPU reference $first"
if [ "$device" = cuda ]; then
  step "CUDA at $first in float, TF32 off: the agreement with the CPU (>= 60 dB)"
  bench --input "$in1" --modes "$modes" --devices cuda --repeats 1 --warmup 1 --tf32 off --reference "$ref" ||
    fail "CUDA $first TF32 off"
  step "CUDA at $first as shipped: float, TF32 on, cuDNN's benchmark mode on"
  bench --input "$in1" --modes "$modes" --devices cuda --repeats "$repeats" --warmup 1 --reference "$ref" ||
    fail "CUDA $first"
  step "CUDA at $first in half (fp16), as OIDN's CUDA device runs: times and agreement"
  bench --input "$in1" --modes "$modes" --devices cuda --repeats "$repeats" --warmup 1 --precision fp16 \
    --reference "$ref" || fail "CUDA $first fp16"
  step "CUDA at $first in bfloat16"
  bench --input "$in1" --modes base,prefilter --devices cuda --repeats "$repeats" --warmup 1 --precision bf16 \
    --reference "$ref" || fail "CUDA $first bf16"
  step "CUDA at $first with cuDNN's benchmark mode off (LibTorch's default, the earlier runs')"
  bench --input "$in1" --modes base,prefilter --devices cuda --repeats 3 --warmup 1 --cudnn-benchmark off \
    --reference "$ref" || fail "CUDA $first benchmark off"
  step "CUDA at $first: one run of three modes traced by Kineto (traces.txt)"
  rm -rf "$work/trace"
  "$build/bin/denoise_npy_bench" --model models/default.dnm --input "$in1" --modes base,prefilter,control \
    --devices cuda --repeats 1 --warmup 1 --trace "$work/trace" >/dev/null 2>"$out/trace.err" ||
    fail "trace (see trace.err)"
  : >"$out/traces.txt"
  for trace in "$work"/trace/*.json; do
    [ -f "$trace" ] || continue  # no trace written: the step above failed already
    python3 bench/gpu/trace_summary.py "$trace" >>"$out/traces.txt" 2>&1 || fail "trace summary $trace"
    echo >>"$out/traces.txt"
  done
  grep -E "traced|outside" "$out/traces.txt"
  gzip -c "$work/trace/prefilter_cuda.json" >"$out/prefilter_cuda.json.gz" 2>/dev/null
else
  step "the device path's settings on the CPU (float; half is refused in one line)"
  bench --input "$in1" --modes "$modes" --devices cpu --repeats 1 --warmup 1 --reference "$ref" ||
    fail "CPU $first"
  bench --input "$in1" --modes base --devices cpu --repeats 1 --warmup 0 --precision bf16 --reference "$ref" ||
    fail "CPU $first bf16"
  "$build/bin/denoise_npy_bench" --model models/default.dnm --input "$in1" --modes base --devices cpu \
    --precision fp16 >"$work/fp16.log" 2>&1 && fail "fp16 ran on the CPU"
  grep -q "half runs on CUDA only" "$work/fp16.log" || fail "fp16 on the CPU: $(tail -1 "$work/fp16.log")"
fi
for size in ${sizes//,/ }; do
  [ "$size" = "$first" ] && continue
  step "$device at $size: float and half in the budget from the device's free memory, then 3 GB tiles"
  precisions=float
  [ "$device" = cuda ] && precisions="float fp16"
  for precision in $precisions; do
    bench --input "$work/inputs/$size" --modes base,prefilter,default --devices "$device" --repeats 3 \
      --warmup 1 --precision "$precision" || fail "$device $size $precision"
  done
  bench --input "$work/inputs/$size" --modes prefilter --devices "$device" --repeats 3 --warmup 1 \
    --max-memory 3 || fail "$device $size 3 GB tiles"
done
step "$device at $first: the temporal default per frame against frame by frame (radius,frames $temporal)"
temporal_bench() {  # PRECISION FILTER (cpu: the per-pixel code; device: tensors on $device)
  "$build/bin/temporal_npy_bench" --model models/default.dnm --input "$in1" --device "$device" \
    --precision "$1" --filter "$2" --radius "${temporal%,*}" --frames "${temporal#*,}" 2>&1 |
    tee "$work/temporal.log"
  [ "${PIPESTATUS[0]}" = 0 ] || fail "temporal $1 $2"
  record "$work/temporal.log"
}
if [ "$device" = cuda ]; then
  temporal_bench float device
  temporal_bench fp16 device
else  # both paths on the CPU: their times, and the tensors' agreement with the loops
  temporal_bench float cpu
  temporal_bench float device
fi
[ "$device" = cuda ] && oidn
finish
