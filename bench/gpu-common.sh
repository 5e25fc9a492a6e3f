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
profile_play_orbit() {  # profile_play_orbit CANOPY-PLAY SCENE.canopy: Nsight Compute on one forest-orbit frame's
  # pixel kernel (the 10th launch) into $O: ncu.txt (details), source-both.csv and source-sass.csv
  # (per-line tables need a -lineinfo build: bench/play/variant.sh li -lineinfo), prof.ncu-rep; prints
  # the headline metrics and the hottest source lines (bench/play/ncu_lines.py)
  local ncu
  ncu=$(command -v ncu || ls /usr/local/cuda/bin/ncu 2>/dev/null || true)
  [[ -n $ncu ]] || { echo "no ncu on this host"; return; }
  mkdir -p "$O/ncu-frames"
  timeout 300 "$ncu" --kernel-name regex:'[Pp]ixel' --launch-skip 9 --launch-count 1 --import-source yes \
    --section SpeedOfLight --section Occupancy --section WarpStateStats --section LaunchStats --section MemoryWorkloadAnalysis \
    --section MemoryWorkloadAnalysis_Tables --section ComputeWorkloadAnalysis --section InstructionStats --section SourceCounters \
    -o "$O/prof" "$1" "$2" --device cuda --size 1920x1080 --frames 10 \
    --camera orbit:elevation=30,distance=55 -o "$O/ncu-frames/f_%04d.exr" > "$O/ncu-run.txt" 2>&1 || echo "ncu failed (see ncu-run.txt)"
  rm -rf "$O/ncu-frames"
  "$ncu" -i "$O/prof.ncu-rep" --page details > "$O/ncu.txt" 2>&1
  "$ncu" -i "$O/prof.ncu-rep" --page source --csv --print-source cuda,sass > "$O/source-both.csv" 2>&1 || echo "no cuda,sass page"
  "$ncu" -i "$O/prof.ncu-rep" --page source --csv --print-source sass > "$O/source-sass.csv" 2>&1 || echo "no sass page"
  grep -E "Duration|Active Threads|Warp Cycles Per Issued|Issued Instructions  |Registers Per|L1/TEX Hit|L2 Hit|Achieved Occ|Local Memory" "$O/ncu.txt"
  python3 bench/play/ncu_lines.py "$O/source-both.csv" 30 2>&1 | head -40
}
