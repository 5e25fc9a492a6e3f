# gpu-common.sh: sourced by the bench/gpu-*.sh scripts on the GPU host (bash, from the repo root,
# with the bundle at .gpu/canopy.tar.xz carried): unpacks the bundle, puts its binaries and
# libraries first on the paths, links the absolute paths the tests were built with, and defines
# $B (bundle), $BIN, $O (= $OUT, the logs), $status and the helpers step, has and gtest.
set -o pipefail  # a failing step piped into tee fails the run
here=$(pwd)
B=/tmp/canopy-bundle
mkdir -p "$B" && tar xJf .gpu/canopy.tar.xz -C "$B"
export PATH=$B/bin:$PATH LD_LIBRARY_PATH=$B/lib BIN=$B/bin
built=${CANOPY_BUILT_AT:-/work/main}  # tests carry absolute paths of the checkout they were built in
mkdir -p "$(dirname "$built")"
[[ -e $built ]] || ln -s "$here" "$built"
[[ -e $(dirname "$built")/shared ]] || ln -s "$B/share/shared" "$(dirname "$built")/shared"
mkdir -p build && { [[ -e build/bin ]] || ln -s "$B/bin" build/bin; }
O=${OUT:-/tmp/out}
mkdir -p "$O"
status=0
nvidia-smi -L | tee "$O/device.txt"; date -u | tee -a "$O/device.txt"
step() { echo "=== $1 $(date -u +%T)"; }
has() { [[ " ${PHASES:-} " == *" $1 "* ]]; }  # has NAME: the script's $PHASES lists NAME
gtest() {  # gtest NAME BINARY [args]: verdicts on stdout, the log under $O; a failure or skip fails the run
  local log=$O/$1.log; shift
  timeout 240 "$@" > "$log" 2>&1 || status=1
  grep -E "^\[ +(OK|FAILED|PASSED|SKIPPED) +\]|RMS" "$log"
  ! grep -q "SKIPPED" "$log" || status=1
}
sampler_checks() {  # sampler_checks LIGHT.vdb: the Haar sampler's users on the device, against the CPU
  CANOPY_HAAR_LIGHT_VDB=$1 gtest test_haar_cuda_oak "$BIN/test_haar_cuda"
  gtest test_play_cuda "$BIN/test_play_cuda"
  gtest test_octreepack_cuda "$BIN/test_octreepack" --gtest_filter='*cuda*'
}
