#!/usr/bin/env bash
# run-gpu.sh: Canopy's GPU checks and benchmarks, by phases, on a machine with an NVIDIA GPU.
#
# The binaries come from a bundle or from a build folder:
#   on the build machine (Release, -DCMAKE_CUDA_ARCHITECTURES=90):
#     cmake --build build && ../shared/scripts/bundle-libs .gpu/canopy.tar.xz build/bin/* -- ../shared
#     (add a grove for the play phase: make -C pipelines scene RESOLUTION=64 DEVICE=cpu O=/tmp/grove,
#      then cp /tmp/grove/scene/grove.canopy /tmp/grove-in/ and append /tmp/grove-in after ../shared)
#   on the GPU machine, from the repository root with .gpu/ beside it:
#     PHASES="tests lbsolve" bash bench/run-gpu.sh
#   or, where the GPU machine has its own build:  BIN=build/bin bash bench/run-gpu.sh
# Logs and Markdown tables go to $OUT (default /tmp/canopy-gpu), one file per step; stdout gets the
# summary lines. Exit status 0 when every step ran and no CUDA test failed or was skipped.
# bench/RESULTS.md says which phase measured each figure.
#
# PHASES (default "tests lbsolve haar octreepack grove play"; run in this order whatever the order given):
#   tests            the CUDA tests against the CPU reference: test_core and test_octreepack (their
#                    cuda cases), test_lbsolve_cuda (every scheme bit for bit, 1/3/8 solves in flight),
#                    test_haar_cuda (synthetic field, then oak_medium's light lit here at 64^3),
#                    test_play_cuda (GPU frames vs the CPU renderer; quarter-size cache path).
#   lbsolve          bench_lbsolve_streams (the dense update's traffic alone, per layout); bench_lbsolve:
#                    node updates/s and fraction of the copy bandwidth per scheme, synthetic plant and
#                    full box at 128^3 and 256^3, then the 57 solves of the synthetic plant and of
#                    oak_medium at 128^3 (on every GPU too where several are visible); canopy-lbsolve
#                    on that oak per --cuda-scheme (light files must be byte-identical) and with
#                    --collision linear; the host CPU's figure.
#   haar             oak_medium's light at 64^3: bench_haar (size at 1 % volume RMS against dense fp32
#                    and ZFP; CPU) and bench_haar_gpu (random trilinear lookups/s against a float4
#                    texture, GPU samples checked against the CPU) per precision.
#   octreepack       bench-octreepack (pack time, size, resident part; the host's CPUs) and
#                    bench-light-packing on oak_medium at 128^3 lit here (light bytes and error per
#                    Haar threshold).
#   grove            the grove through the Make rules on the GPU (voxelize, lbsolve, lbsolve --scene,
#                    haar, octreepack) at GROVE_RESOLUTION, played at 1080p with the sun moving.
#   play             bench-play: the synthetic plant and 400-instance forest (orbit and walk), plus the
#                    grove where GROVE or the bundle's grove-in/grove.canopy exists, 1920x1080, 1 GiB
#                    cache, FRAMES frames, once per binary of PLAY_BINS.
#   stereo           the real forest through the Make rules on the GPU (the shared plants at 128^3,
#                    FOREST_N instances on a disk of FOREST_RADIUS m: ~8.9 m apart by default), walked
#                    at 1.8 m eye height (120 frames, 1080p, 1 GiB cache): canopy-play mono, mono in two
#                    bands on one GPU (--tiles 2), and bench-stereo (IPD 0.064 m: the second eye
#                    reprojected against traced in full, its time and image error) at --stereo-spread
#                    0.5, 0.65 (default), 0.75 and 1, and on a high orbit.
#   forest           canopy-play on real-plant forests built by the Make rules (the stereo phase's build
#                    and walk), each run 120 frames, 1 GiB cache, --json, canopy-play's defaults (at
#                    3840x2160 --adaptive auto samples adaptively: the size cell says so): one table in $OUT/forest.md,
#                    the reports forest_*.json, each camera's last frame as forest-*.png (480x270):
#                    - the 400-instance forest, high orbit (elevation 25 deg, 300 m: the whole forest
#                      in view; a quarter turn), 1920x1080 and 3840x2160
#                    - the same, low orbit (elevation 10 deg, 90 m, a quarter turn), both sizes
#                    - the same, the eye-level walk of the stereo phase, both sizes
#                    - FOREST_BIG_N (4000) instances on ten times the area (FOREST_BIG_RADIUS 316 m), the
#                      same plants and walk, 1920x1080; the ratio of its median to the 400 walk's
#                    - the 400 walk at 1920x1080 with a 256 MiB cache (a quarter), then 64 MiB (FOREST_CACHES
#                      "256 64": the 400 forest's pages, ~216 MB at 128^3, fit in 256): medians and ratios
#   dials            canopy-play's quality dials on the stereo phase's real forest (400 instances, 128^3
#                    plants): the three cameras of the forest phase at FOREST_SIZES, FRAMES (120) frames, 1
#                    GiB cache, with the defaults and with each of DIALS (flag sets separated by ';', default
#                    "--step 1;--stop-opacity 0.99;--step 1 --stop-opacity 0.99"): the median frame, its
#                    ratio to the defaults', and the converged first frame of each camera against the
#                    defaults' (bench-image-diff: RMS relative to the covered mean RGB); $OUT/dials.md.
#   detail           oak_medium through the Make rules with a detail lattice (`make plants DETAIL=...`, one
#                    plant, DEVICE=cuda): light 128 / detail 1024 and light 136 / detail 1088, the make
#                    timed, the .canopy's bytes; then the 1080p close-ups (120 frames, 1 GiB cache, two
#                    rounds alternated) that frame the tree's 16 m height with two lenses: 40° at 22 m
#                    and 30° at 29.87 m (distance = 8.0 m / tan(fov / 2)); one table in $OUT/detail.md.
#                    The sampled voxels' widths in pixels are a CPU count (bench/RESULTS.md, "Detail
#                    lattices").
#   profile-lbsolve  Nsight Compute on one pull launch in the middle of a solve (clocks and caches
#                    left alone): duration and DRAM bytes per lattice node against the model's 156 B.
#   profile-play     Nsight Compute on one forest-orbit frame's pixel kernel of PROFILE_BIN (PROFILE_SCENE=real:
#                    the real forest of the dials phase, mid-walk, built if missing) (build it
#                    with -lineinfo for the per-line table: bench/play/variant.sh li -lineinfo), the
#                    hottest source lines (bench/play/ncu_lines.py) and the kernel's SASS.
#
# Settings (environment):
#   BIN               folder of the binaries (default: the unpacked bundle's bin/)
#   BUNDLE            the bundle (default .gpu/canopy.tar.xz)
#   CANOPY_BUILT_AT   checkout the tests were built in (default /work/main): its path is linked to this
#                     tree, and its ../shared to the bundle's shared/, so that their absolute paths hold
#   SHARED            the shared assets folder (default: the bundle's share/shared, else ../shared)
#   LB_BINS           bench_lbsolve binaries run in turn (default bench_lbsolve; e.g. "bench_lbsolve
#                     bench_lbsolve-prev" for an A/B of two builds on one machine)
#   LB_SCHEMES        default shift,pull (also shift-split, push)
#   LB_IN_FLIGHT      solves in flight per GPU, default 1 (e.g. 1,3)
#   LB_SOLVES_SIZES   synthetic plants whose 57 solves are timed, default 128
#   HAAR_PRECISIONS   default "quant fp16 fp32"
#   GROVE_RESOLUTION  default 96;  SHADOWS: the grove phase's shadow methods, default "map" (e.g. "map cone")
#   GROVE             a packed grove for the play phase
#   PLAY_BINS         bench-play binaries run in turn (default bench-play; a binary may appear twice, to
#                     alternate builds made by bench/play/variant.sh)
#   PLAY_VARIANTS     bench-play's methods, default "--shadows map" (e.g. "--shadows map --shadows cone
#                     --shadows map-stop99"); FRAMES default 120
#   PNGS=1            keep the first play run's last frames as $OUT/play-*.png
#   SMALL_CACHE=1     the play phase again with a 32 MiB cache (less than the forest's file)
#   PROFILE_BIN       default canopy-play;  GTEST_TIMEOUT per CUDA test binary, default 300 s
#   FOREST_N, FOREST_RADIUS  the stereo and forest phases' forest (default 400 instances on 100 m)
#   FOREST_BIG_N, FOREST_BIG_RADIUS  the forest phase's large forest (default 4000 on 316 m)
#   FOREST_RESOLUTION the forests' plants, cells per axis (default 128)
#   FOREST_SIZES      the forest phase's frame sizes, default "1920x1080 3840x2160" (the first is the
#                     size of the large forest and small-cache runs); FRAMES (120) frames per run;
#                     FOREST_CACHES: the small-cache runs' budgets in MiB (default "256 64")
#   DIALS             the dials phase's flag sets, ';' between them (each against the defaults)
#   DETAIL_CONFIGS    the detail phase's plants, LIGHT:DETAIL (default "128:1024 136:1088"); DETAIL_SHOTS its
#                     close-ups, DETAIL:FOV:DISTANCE (default "1024:40:22 1024:30:29.87 1088:40:22")
#   BENCH_DEVICE      default cuda; cpu builds the forests and runs the forest phase on the CPU, to
#                     check the phase end to end on a machine without a GPU, at tiny settings:
#                     BENCH_DEVICE=cpu FOREST_RESOLUTION=32 FOREST_N=40 FOREST_BIG_N=400 \
#                     FOREST_SIZES="160x90 320x180" FRAMES=3 BIN=build/bin PHASES=forest bash bench/run-gpu.sh
set -uo pipefail
here=$(pwd)
O=${OUT:-/tmp/canopy-gpu}
W=${WORK:-/tmp/canopy-gpu-work}
mkdir -p "$O" "$W"
status=0

# --- binaries and paths ------------------------------------------------------------------------
if [[ -z ${BIN:-} ]]; then
  bundle=${BUNDLE:-.gpu/canopy.tar.xz}
  [[ -f $bundle ]] || { echo "run-gpu.sh: no BIN and no bundle at $bundle" >&2; exit 1; }
  B=$W/bundle
  mkdir -p "$B" && tar xJf "$bundle" -C "$B" || exit 1
  BIN=$B/bin
  export LD_LIBRARY_PATH=$B/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
  [[ -d $B/share/shared ]] && SHARED=${SHARED:-$B/share/shared}
  [[ -z ${GROVE:-} && -f $B/share/grove-in/grove.canopy ]] && GROVE=$B/share/grove-in/grove.canopy
fi
BIN=$(cd "$BIN" 2>/dev/null && pwd) || { echo "run-gpu.sh: no folder $BIN (BIN)" >&2; exit 1; }
export PATH=$BIN:$PATH
SHARED=$(cd "${SHARED:-$here/../shared}" 2>/dev/null && pwd) || { echo "run-gpu.sh: no shared assets folder (SHARED)" >&2; exit 1; }
built=${CANOPY_BUILT_AT:-/work/main}  # the tests carry absolute paths of the checkout they were built in
if [[ $built != "$here" ]]; then
  mkdir -p "$(dirname "$built")"
  [[ -e $built ]] || ln -s "$here" "$built"
fi
# (also where this tree is the checkout itself: its ../shared may be missing on the GPU machine)
[[ -e $(dirname "$built")/shared ]] || ln -s "$SHARED" "$(dirname "$built")/shared"
mkdir -p build && { [[ -e build/bin ]] || ln -s "$BIN" build/bin; }
OAK=$SHARED/assets/plants/oak_medium.glb

PHASES=${PHASES:-tests lbsolve haar octreepack grove play}
has() { [[ " $PHASES " == *" $1 "* ]]; }
for p in $PHASES; do
  case $p in tests|lbsolve|haar|octreepack|grove|play|stereo|forest|dials|detail|profile-lbsolve|profile-play) ;;
    *) echo "run-gpu.sh: unknown phase '$p'" >&2; exit 1 ;;
  esac
done

step() { echo "=== $1 $(date -u +%T)"; }
fail() { echo "FAILED: $*"; status=1; }
need() {  # need BINARY...: true when every one is in BIN, else a failure naming the missing ones
  local b ok=0
  for b in "$@"; do [[ -x $BIN/$b ]] || { fail "$b is not in $BIN"; ok=1; }; done
  return $ok
}
run() {  # run LOG COMMAND...: the command's stdout and stderr into $O/LOG; a failure fails the run
  local log=$O/$1; shift
  "$@" > "$log" 2>&1 || fail "$* (exit $?, see $log)"
}
gtest() {  # gtest NAME BINARY [args]: the verdicts on stdout, the log in $O; a failure or a skip fails the run
  local log=$O/$1.log exe=$2; shift 2
  need "$exe" || return
  timeout "${GTEST_TIMEOUT:-300}" "$BIN/$exe" "$@" > "$log" 2>&1 || fail "$exe (see $log)"
  grep -E "^\[ +(OK|FAILED|PASSED|SKIPPED) +\]" "$log"
  ! grep -q "SKIPPED" "$log" || fail "$exe: skipped cases (no GPU visible?)"
}
oak() {  # oak N: oak_medium voxelised at N^3 and lit on the GPU, once per run: $W/oakN.{density,light}.vdb
  local n=$1
  [[ -f $W/oak$n.light.vdb ]] && return
  need canopy-voxelize canopy-lbsolve || return
  if ! { canopy-voxelize "$OAK" -o "$W/oak$n.density.vdb" --resolution "$n" -q &&
         canopy-lbsolve "$W/oak$n.density.vdb" -o "$W/oak$n.light.vdb" --device cuda -q; }; then
    fail "oak_medium at $n^3"; return 1
  fi
}
seconds() { python3 -c 'import json, sys; print(round(json.load(open(sys.argv[1]))["seconds"], 3))' "$1"; }
dev=${BENCH_DEVICE:-cuda}
walk=$W/forest-walk.json  # the forests' walk: eye level (1.8 m), straight through the middle, looking ahead and slightly up
high=orbit:elevation=25,distance=300,turns=0.25  # the forests' high orbit: the whole forest in view (at 150 m its near edge and sides are cut)
low=orbit:elevation=10,distance=90,turns=0.25    # and low orbit
forest_canopy() {  # forest_canopy N RADIUS: the path of forest_build's forest
  echo "$W/forest${FOREST_RESOLUTION:-128}/forest/forest-n$1-r$2.canopy"
}
forest_build() {  # forest_build N RADIUS: N instances of the shared plants on a disk of RADIUS m, through the
  # Make rules on BENCH_DEVICE, at $(forest_canopy N RADIUS) (one folder per plant resolution: its forests
  # share the plants); writes $walk; false (and the run failed) when the build fails
  local t0=$SECONDS res=${FOREST_RESOLUTION:-128} name=forest-n$1-r$2
  echo '{"keyframes":[{"frame":0,"position":[-70,1.8,-8],"target":[-40,3.0,-2],"fov":60},{"frame":119,"position":[70,1.8,8],"target":[100,3.0,14],"fov":60}]}' > "$walk"
  if ! timeout 600 make -j8 -C pipelines forest PLANTS="$SHARED/assets/plants" BIN="$BIN" O="$W/forest$res" DEVICE="$dev" \
      RESOLUTION="$res" FOREST_NAME="$name" FOREST_N="$1" FOREST_RADIUS="$2" FOREST_FRAMES=1 PLAY_SIZE=320x180 \
      > "$O/${name}_make.log" 2>&1; then
    fail "make forest $name (see $O/${name}_make.log)"; return 1
  fi
  echo "forest of $1 instances on $2 m (plants at $res^3, $dev): make $((SECONDS - t0)) s;" \
    "$(canopy-octreepack info "$(forest_canopy "$1" "$2")" 2>&1 | head -1)"
}

{ nvidia-smi -L; date -u; echo "commit $(git rev-parse --short HEAD 2>/dev/null || echo unknown)"; } | tee "$O/device.txt"

# --- phases ------------------------------------------------------------------------------------
if has tests; then
  step tests
  gtest test_core_cuda test_core --gtest_filter='*cuda*'
  gtest test_octreepack_cuda test_octreepack --gtest_filter='*cuda*'
  gtest test_lbsolve_cuda test_lbsolve_cuda
  gtest test_haar_cuda_synthetic test_haar_cuda
  oak 64 && CANOPY_HAAR_LIGHT_VDB=$W/oak64.light.vdb gtest test_haar_cuda_oak test_haar_cuda
  gtest test_play_cuda test_play_cuda
fi

if has lbsolve; then
  step lbsolve
  if need bench_lbsolve_streams; then
    run lbsolve_streams.md timeout 300 bench_lbsolve_streams --sizes 128,256
    grep -E "^\|" "$O/lbsolve_streams.md" | head -30
  fi
  oak 128
  for b in ${LB_BINS:-bench_lbsolve}; do
    need "$b" || continue
    run "lbsolve_$b.md" timeout 600 "$b" --device cuda --sizes 128,256 --fill plant,full \
      --schemes "${LB_SCHEMES:-shift,pull}" --in-flight "${LB_IN_FLIGHT:-1}" --iterations 400 \
      --solves-sizes "${LB_SOLVES_SIZES:-128}" --lattices "$W/oak128.density.vdb"
    grep -E "^copy|^\| " "$O/lbsolve_$b.md"
  done
  if need canopy-lbsolve; then  # the tool end to end (read, 57 solves, write) per scheme and collision
    for s in shift shift-split push pull; do
      t0=$(date +%s.%N)
      run "lbsolve_oak128_$s.json" canopy-lbsolve "$W/oak128.density.vdb" -o "$W/oak128.$s.light.vdb" --device cuda --cuda-scheme "$s" --json -q
      echo "canopy-lbsolve oak128 --cuda-scheme $s: $(awk "BEGIN{printf \"%.3f\", $(date +%s.%N) - $t0}") s process wall, report seconds $(seconds "$O/lbsolve_oak128_$s.json")"
    done
    for s in shift-split push pull; do
      if cmp -s "$W/oak128.shift.light.vdb" "$W/oak128.$s.light.vdb"; then echo "light file of $s: byte-identical to shift's"
      else fail "light file of $s differs from shift's"; fi
    done
    run lbsolve_oak128_linear.json canopy-lbsolve "$W/oak128.density.vdb" -o "$W/oak128.linear.light.vdb" --device cuda --collision linear --json -q
    echo "canopy-lbsolve oak128 --collision linear: report seconds $(seconds "$O/lbsolve_oak128_linear.json")"
    rm -f "$W"/oak128.*.light.vdb
  fi
  if need bench_lbsolve; then
    run lbsolve_cpu.md timeout 300 bench_lbsolve --device cpu --sizes 128 --solves-sizes "" --iterations 16
    grep -E "^\| " "$O/lbsolve_cpu.md"
  fi
fi

if has haar; then
  step haar
  oak 64
  if need bench_haar bench_haar_gpu; then
    for p in ${HAAR_PRECISIONS:-quant fp16 fp32}; do
      run "haar_$p.md" timeout 600 bench_haar "$W/oak64.light.vdb" --precision "$p" --write-chaar "$W/oak64.$p.chaar"
      grep -E "^\| (\.chaar at|ratio vs dense|\.chaar / ZFP)" "$O/haar_$p.md"
      run "haar_gpu_$p.md" timeout 300 bench_haar_gpu "$W/oak64.$p.chaar"
      grep -E "all [0-9]+|^check:|compressed on device" "$O/haar_gpu_$p.md"
    done
  fi
fi

if has octreepack; then
  step octreepack
  if need bench-octreepack; then
    run octreepack.md timeout 300 bench-octreepack "$W/octreepack"
    grep -E "^\| " "$O/octreepack.md"
  fi
  oak 128
  if need bench-light-packing canopy-haar canopy-octreepack; then
    run light_packing.md timeout 600 bench-light-packing "$W/light-packing" "$W/oak128.density.vdb" "$W/oak128.light.vdb" \
      --thresholds 0,0.01,0.03,0.05,0.1
    grep -E "^\| " "$O/light_packing.md"
  fi
fi

if has grove && need canopy-voxelize canopy-lbsolve canopy-haar canopy-octreepack canopy-play; then
  step grove
  g=$W/grove/scene/grove.canopy
  run grove_make.log timeout 600 make -C pipelines scene SCENE="$SHARED/assets/scenes/grove.glb" BIN="$BIN" O="$W/grove" \
    DEVICE=cuda RESOLUTION="${GROVE_RESOLUTION:-96}"
  canopy-octreepack info "$g" 2>&1 | grep -iE "scene light|version" | head -3
  for m in ${SHADOWS:-map}; do
    run "grove_play_$m.json" timeout 300 canopy-play "$g" --device cuda --size 1920x1080 --frames 120 --cache-mb 1024 --shadows "$m" \
      --camera orbit:turns=0.5,elevation=20 --sun orbit:azimuth=40,elevation=30,turns=0.5 --json -q
    python3 -c 'import json, sys; r = json.load(open(sys.argv[1])); print("grove 1080p", sys.argv[2], {k: r[k] for k in r if k in ("frame_ms_median", "frame_ms_p95", "first_complete_frame_s", "scene_light_bases", "sun_bases", "lit_models")})' \
      "$O/grove_play_$m.json" "$m"
  done
  run grove_png.log canopy-play "$g" --device cuda --size 640x360 -o "$O/grove.png" -q
fi

if has play; then
  step play
  extra=()
  [[ -n ${GROVE:-} ]] && extra=(--extra grove="$GROVE")
  i=0
  for b in ${PLAY_BINS:-bench-play}; do
    need "$b" || continue
    i=$((i + 1))
    echo "--- $b (run $i)"
    # shellcheck disable=SC2086  # PLAY_VARIANTS is a list of options
    run "play_$i.md" timeout 600 "$b" "$W/play-$i" --device cuda --size 1920x1080 --frames "${FRAMES:-120}" --cache-mb 1024 \
      ${PLAY_VARIANTS:---shadows map} "${extra[@]}"
    grep -E "^\| " "$O/play_$i.md"
    if [[ $i == 1 && ${PNGS:-0} == 1 ]]; then
      for n in plant forest-orbit forest-walk grove; do [[ -e $W/play-1/$n.png ]] && cp "$W/play-1/$n.png" "$O/play-$n.png"; done
    fi
  done
  if [[ ${SMALL_CACHE:-0} == 1 ]] && need bench-play; then
    run play_small_cache.md timeout 600 bench-play "$W/play-small-cache" --device cuda --size 1920x1080 --frames "${FRAMES:-120}" --cache-mb 32
    grep -E "^\| " "$O/play_small_cache.md"
  fi
fi

if has stereo && need canopy-voxelize canopy-lbsolve canopy-haar canopy-octreepack canopy-play bench-stereo; then
  step stereo
  f=$(forest_canopy "${FOREST_N:-400}" "${FOREST_RADIUS:-100}")
  forest_build "${FOREST_N:-400}" "${FOREST_RADIUS:-100}"
  for tiles in 1 2; do
    run "forest_walk_tiles$tiles.json" timeout 300 canopy-play "$f" --device cuda --size 1920x1080 --frames 120 --cache-mb 1024 \
      --camera "$walk" --tiles "$tiles" --json -q
    python3 -c 'import json, sys; r = json.load(open(sys.argv[1])); print("forest walk 1080p mono, bands", sys.argv[2], r["frame_ms_median"], r["frame_ms_p95"], r["first_complete_frame_s"], [b["rows"] for b in r["bands"]], [round(b["ms_median"], 2) for b in r["bands"]])' \
      "$O/forest_walk_tiles$tiles.json" "$tiles"
  done
  for spread in 0.5 0.65 0.75 1; do
    run "stereo_walk_$spread.md" timeout 600 bench-stereo "$f" --camera "$walk" --device cuda --size 1920x1080 --frames 120 --ipd 0.064 \
      --cache-mb 1024 --error-frames 0,40,80 --stereo-spread "$spread" --png "$O/stereo-walk-$spread"
    tail -1 "$O/stereo_walk_$spread.md"
  done
  run stereo_orbit.md timeout 600 bench-stereo "$f" --camera orbit:elevation=25,distance=150,turns=0.25 --device cuda --size 1920x1080 \
    --frames 120 --ipd 0.064 --cache-mb 1024 --error-frames 0,60
  tail -1 "$O/stereo_orbit.md"
fi

forest_play() {  # forest_play ID SCENE CAMERA SIZE CACHE_MB: one timed canopy-play run, its report in $O/forest_ID.json
  run "forest_$1.json" timeout 300 canopy-play "$2" --device "$dev" --size "$4" --frames "${FRAMES:-120}" --cache-mb "$5" \
    --camera "$3" --json -q
}
forest_row() {  # forest_row ID SCENE CAMERA SIZE FRAME: the table row of $O/forest_ID.json
  python3 - "$O/forest_$1.json" "$2" "$3" "$4" "$5" <<'PY'
import json, sys
path, scene, camera, size, png = sys.argv[1:]
try:
    r = json.load(open(path))
    first = r["first_complete_frame_s"]  # -1: no frame was complete
    cells = [f"{r['frame_ms_median']:.2f}", f"{r['frame_ms_p95']:.2f}", f"{first:.2f}" if first >= 0 else "none"]
    if "adaptive" in r:  # --adaptive auto at 3840x2160 and larger
        a = r["adaptive"]
        size += f" (adaptive {a['tolerance']:g}, {100 * a['traced_fraction_mean']:.0f} % traced)"
except (OSError, ValueError, KeyError, TypeError):
    cells = ["failed"] * 3
print(f"| {scene} | {camera} | {size} | " + " | ".join(cells) + f" | {png} |")
PY
}
forest_png() {  # forest_png NAME SCENE CAMERA: the camera's last frame at 480x270 (a run of its own) -> $O/forest-NAME.png
  local d=$W/forest-png/$1 last
  rm -rf "$d" && mkdir -p "$d"
  printf -v last 'f_%04d.png' $((${FRAMES:-120} - 1))
  run "forest-$1.png.log" timeout 300 canopy-play "$2" --device "$dev" --size 480x270 --frames "${FRAMES:-120}" --cache-mb 1024 \
    --camera "$3" -o "$d/f_%04d.png" -q
  if [[ -f $d/$last ]]; then cp "$d/$last" "$O/forest-$1.png"; else fail "no last frame $d/$last"; fi
  rm -rf "$d"
  [[ -s $O/forest-$1.png.log ]] || rm -f "$O/forest-$1.png.log"
}

if has forest && need canopy-voxelize canopy-lbsolve canopy-haar canopy-octreepack canopy-play; then
  step forest
  t0=$SECONDS
  n=${FOREST_N:-400} r=${FOREST_RADIUS:-100} bn=${FOREST_BIG_N:-4000} br=${FOREST_BIG_RADIUS:-316}
  read -ra sizes <<< "${FOREST_SIZES:-1920x1080 3840x2160}"
  f=$(forest_canopy "$n" "$r") big=$(forest_canopy "$bn" "$br")
  forest_build "$n" "$r"
  forest_build "$bn" "$br"
  t=$O/forest.md
  { echo "| scene | camera | size | median ms | p95 ms | first complete frame s | last frame |"
    echo "|---|---|---|---|---|---|---|"; } > "$t"
  for cam in high low walk; do
    case $cam in
      high) spec=$high label="high orbit (25°, 300 m)" ;;
      low) spec=$low label="low orbit (10°, 90 m)" ;;
      walk) spec=$walk label="eye-level walk" ;;
    esac
    forest_png "n$n-$cam" "$f" "$spec"
    for size in "${sizes[@]}"; do
      forest_play "n$n-$cam-$size" "$f" "$spec" "$size" 1024
      forest_row "n$n-$cam-$size" "$n trees, $r m" "$label" "$size" "forest-n$n-$cam.png" >> "$t"
    done
  done
  forest_png "n$bn-walk" "$big" "$walk"
  forest_play "n$bn-walk-${sizes[0]}" "$big" "$walk" "${sizes[0]}" 1024
  forest_row "n$bn-walk-${sizes[0]}" "$bn trees, ${br} m" "eye-level walk" "${sizes[0]}" "forest-n$bn-walk.png" >> "$t"
  caches=${FOREST_CACHES:-256 64}
  for mb in $caches; do
    forest_play "n$n-walk-${sizes[0]}-cache$mb" "$f" "$walk" "${sizes[0]}" "$mb"
    forest_row "n$n-walk-${sizes[0]}-cache$mb" "$n trees, $r m" "eye-level walk, $mb MiB cache" "${sizes[0]}" "forest-n$n-walk.png" >> "$t"
  done
  python3 - "$O" "$n" "$bn" "${sizes[0]}" "${FRAMES:-120}" "$high" "$low" "$caches" "$dev" >> "$t" <<'PY'
import json, sys
out, n, bn, size, frames, high, low, caches, dev = sys.argv[1:]
def report(run):
    try:
        return json.load(open(f"{out}/forest_{run}.json"))
    except (OSError, ValueError):
        return None
walk, bigwalk = report(f"n{n}-walk-{size}"), report(f"n{bn}-walk-{size}")
print()
if walk and bigwalk:
    print(f"- {bn} / {n} trees, walk at {size}, median: {bigwalk['frame_ms_median']:.2f} / {walk['frame_ms_median']:.2f} ms "
          f"= **{bigwalk['frame_ms_median'] / walk['frame_ms_median']:.2f}x**")
for mb in caches.split():
    small = report(f"n{n}-walk-{size}-cache{mb}")
    if walk and small:  # the cache holds at most the file's pages: cache_mb is what it got
        print(f"- {n} trees, walk at {size}, {mb} MiB / 1 GiB cache (cache {small['cache_mb']:.0f} / {walk['cache_mb']:.0f} "
              f"MiB, the forest's pages {walk['scene_page_mb']:.0f} MiB), median: {small['frame_ms_median']:.2f} / "
              f"{walk['frame_ms_median']:.2f} ms = **{small['frame_ms_median'] / walk['frame_ms_median']:.2f}x**; hit rate "
              f"{100 * small['cache_hit_rate']:.1f} / {100 * walk['cache_hit_rate']:.1f} %, evictions {small['evictions']} / "
              f"{walk['evictions']}, {small['mb_streamed']:.0f} / {walk['mb_streamed']:.0f} MiB streamed")
if bigwalk:
    print(f"- the {bn}-tree forest's pages: {bigwalk['scene_page_mb']:.0f} MiB")
if walk:
    print(f"- LB-lit models {walk['lit_models']}, coarse scene light bases {walk['scene_light_bases']}"
          + (" (the forest rule packs no `canopy-lbsolve --scene` light)" if walk['scene_light_bases'] == 0 else ""))
print(f"\n{frames} frames a run, `canopy-play FOREST --device {dev} --size WxH --frames {frames} "
      f"--cache-mb 1024 --camera CAMERA --json`; cameras: high `{high}`, low `{low}`, walk `forest-walk.json` "
      "(1.8 m eye height, x -70 to 70 m through the middle, 60° field of view). The last frames: 480x270, "
      "a run of their own of the same camera (1 GiB cache), not the timed run's image.")
PY
  cat "$t"
  echo "forest phase: $((SECONDS - t0)) s"
fi

if has dials && need canopy-voxelize canopy-lbsolve canopy-haar canopy-octreepack canopy-play bench-image-diff; then
  step dials
  t0=$SECONDS
  f=$(forest_canopy "${FOREST_N:-400}" "${FOREST_RADIUS:-100}")
  [[ -f $f ]] || forest_build "${FOREST_N:-400}" "${FOREST_RADIUS:-100}"
  read -ra sizes <<< "${FOREST_SIZES:-1920x1080 3840x2160}"
  IFS=';' read -ra dials <<< "${DIALS:---step 1;--stop-opacity 0.99;--step 1 --stop-opacity 0.99}"
  dials=("" "${dials[@]}")
  for cam in high low walk; do
    spec=${!cam}
    for size in "${sizes[@]}"; do
      for k in "${!dials[@]}"; do
        read -ra flags <<< "${dials[$k]}"
        id=$cam-$size-$k
        run "dials_$id.json" timeout 300 canopy-play "$f" --device "$dev" --size "$size" --frames "${FRAMES:-120}" --cache-mb 1024 \
          --camera "$spec" "${flags[@]}" --json -q
        run "dials_$id.exr.log" timeout 300 canopy-play "$f" --device "$dev" --size "$size" --frames 1 --converge --cache-mb 1024 \
          --camera "$spec" "${flags[@]}" -o "$W/dials_$id.exr" -q
        ((k == 0)) || run "dials_$id.diff.json" bench-image-diff "$W/dials_$id.exr" "$W/dials_$cam-$size-0.exr" --json -q
      done
    done
  done
  (IFS=';'; python3 - "$O" "${dials[*]}" "${sizes[*]}" >> "$O/dials.md") <<'PY'
import json, sys
out, dials, sizes = sys.argv[1], sys.argv[2].split(";"), sys.argv[3].split(";")
def load(name):
    try:
        return json.load(open(f"{out}/{name}"))
    except (OSError, ValueError):
        return None
print("| camera | size | flags | median ms (p95) | / defaults | RMS vs defaults (first frame, converged) |")
print("|---|---|---|---|---|---|")
for cam in ("high", "low", "walk"):
    for size in sizes:
        base = load(f"dials_{cam}-{size}-0.json")
        for k, flags in enumerate(dials):
            r = load(f"dials_{cam}-{size}-{k}.json")
            if r is None:
                print(f"| {cam} | {size} | {flags or '(defaults)'} | (no report) | | |")
                continue
            d = load(f"dials_{cam}-{size}-{k}.diff.json")
            ratio = f"{r['frame_ms_median'] / base['frame_ms_median']:.3f}" if base else ""
            rms = f"{100 * d['relative']:.2f} %" if d else ""
            print(f"| {cam} | {size} | {flags or '(defaults)'} | {r['frame_ms_median']:.2f} ({r['frame_ms_p95']:.2f}) | {ratio} | {rms} |")
PY
  cat "$O/dials.md"
  echo "dials phase: $((SECONDS - t0)) s"
fi

if has detail && need canopy-voxelize canopy-lbsolve canopy-haar canopy-octreepack canopy-play; then
  step detail
  t0=$SECONDS
  mkdir -p "$W/detail-in" && ln -sf "$OAK" "$W/detail-in/oak_medium.glb"
  configs=${DETAIL_CONFIGS:-128:1024 136:1088}
  for rd in $configs; do
    r=${rd%:*} d=${rd#*:} dir=$W/detail-$d
    rm -rf "$dir"
    s0=$(date +%s.%N)
    if timeout 600 make -j8 -C pipelines plants PLANTS="$W/detail-in" BIN="$BIN" O="$dir" DEVICE="$dev" RESOLUTION="$r" \
        DETAIL="$d" > "$O/detail-${d}_make.log" 2>&1; then
      echo "oak_medium light $r / detail $d: make $(awk "BEGIN{printf \"%.2f\", $(date +%s.%N) - $s0}") s," \
        "$(stat -c %s "$dir/plants/oak_medium.canopy") B"
      canopy-octreepack info "$dir/plants/oak_medium.canopy" --json > "$O/detail-${d}_info.json" 2>&1
    else
      fail "make plants DETAIL=$d (see $O/detail-${d}_make.log)"
    fi
  done
  shots=${DETAIL_SHOTS:-1024:40:22 1024:30:29.87 1088:40:22}
  for round in 1 2; do
    for s in $shots; do
      IFS=: read -r d fov dist <<< "$s"
      f=$W/detail-$d/plants/oak_medium.canopy
      [[ -f $f ]] && run "detail_${d}_fov${fov}_$round.json" canopy-play "$f" --device "$dev" --size 1920x1080 --frames "${FRAMES:-120}" \
        --cache-mb 1024 --camera "orbit:elevation=5,distance=$dist,turns=0.25,fov=$fov" --json -q
    done
  done
  python3 - "$O" "$configs" "$shots" >> "$O/detail.md" <<'PY'
import json, os, sys
out, configs, shots = sys.argv[1], sys.argv[2].split(), sys.argv[3].split()
print("| light / detail | `.canopy` MB | lens, distance | median ms (two runs) | p95 ms | first complete frame s |")
print("|---|---:|---|---|---|---|")
light = {c.split(":")[1]: c.split(":")[0] for c in configs}
for s in shots:
    d, fov, dist = s.split(":")
    try:
        runs = [json.load(open(f"{out}/detail_{d}_fov{fov}_{r}.json")) for r in (1, 2)]
        info = json.load(open(f"{out}/detail-{d}_info.json"))
    except (OSError, ValueError):
        print(f"| {light[d]} / {d} | | {fov}°, {dist} m | (no report) | | |")
        continue
    j = lambda k, f: " / ".join(f.format(r[k]) for r in runs)
    print(f"| {light[d]} / {d} | {info['file_bytes'] / 1e6:.1f} | {fov}°, {dist} m | {j('frame_ms_median', '{:.2f}')} | "
          f"{j('frame_ms_p95', '{:.2f}')} | {j('first_complete_frame_s', '{:.2f}')} |")
PY
  cat "$O/detail.md"
  echo "detail phase: $((SECONDS - t0)) s"
fi

if has profile-lbsolve && need bench_lbsolve; then
  step profile-lbsolve
  ncu=$(command -v ncu || ls /usr/local/cuda/bin/ncu 2>/dev/null || true)
  if [[ -z $ncu ]]; then fail "profile-lbsolve: no ncu on this machine"; else
    for n in 128 256; do
      run "ncu_pull_$n.txt" timeout 300 "$ncu" --kernel-name regex:pullLeafKernel --launch-skip 50 --launch-count 5 \
        --clock-control none --cache-control none \
        --metrics gpu__time_duration.sum,dram__bytes_read.sum,dram__bytes_write.sum,sm__cycles_active.avg,gpc__cycles_elapsed.max \
        "$BIN/bench_lbsolve" --device cuda --sizes "$n" --fill plant --schemes pull --in-flight 1 --iterations 100 --solves-sizes ""
      python3 - "$O/ncu_pull_$n.txt" "$n" <<'PY'
import re, sys
text, n = open(sys.argv[1]).read(), int(sys.argv[2])
scale = {"byte": 1, "Kbyte": 1e3, "Mbyte": 1e6, "Gbyte": 1e9, "KB": 1e3, "MB": 1e6, "GB": 1e9,
         "nsecond": 1e-9, "usecond": 1e-6, "msecond": 1e-3, "ns": 1e-9, "us": 1e-6, "ms": 1e-3}
def values(name):
    return [float(v.replace(",", "")) * scale.get(u, 1) for u, v in re.findall(name + r"\s+(\S+)\s+([\d,\.]+)", text)]
r, w, t = values("dram__bytes_read.sum"), values("dram__bytes_write.sum"), values("gpu__time_duration.sum")
if not (r and w and t):
    sys.exit("no metrics in " + sys.argv[1])
inner = (n - 2) ** 3
print(f"pull {n}^3, {len(t)} launches: {min(t) * 1e6:.1f}-{max(t) * 1e6:.1f} us; DRAM per interior node "
      f"{sum(r) / len(r) / inner:.1f} B read + {sum(w) / len(w) / inner:.1f} B written (model 80 + 76 = 156)")
PY
    done
  fi
fi

if has profile-play; then
  step profile-play
  pb=${PROFILE_BIN:-canopy-play}
  ncu=$(command -v ncu || ls /usr/local/cuda/bin/ncu 2>/dev/null || true)
  forest=$W/play-1/forest.canopy
  camera=orbit:elevation=30,distance=55
  if [[ ${PROFILE_SCENE:-synthetic} == real ]]; then  # the real forest (built as the dials phase builds it), mid-walk
    forest=$(forest_canopy "${FOREST_N:-400}" "${FOREST_RADIUS:-100}")
    [[ -f $forest ]] || forest_build "${FOREST_N:-400}" "${FOREST_RADIUS:-100}"
    camera=$W/walk-mid.json
    echo '{"keyframes":[{"frame":0,"position":[0,1.8,0],"target":[30,3.0,6],"fov":60}]}' > "$camera"
  elif [[ ! -f $forest ]] && need bench-play; then  # the play phase's forest, or a short run that writes it
    run play_profile_scene.md timeout 300 bench-play "$W/play-1" --device cuda --size 1920x1080 --frames 2 --cache-mb 1024 --shadows map
  fi
  if [[ -z $ncu ]]; then fail "profile-play: no ncu on this machine"; elif need "$pb" && [[ -f $forest ]]; then
    # the 10th launch of the pixel kernel: one converged frame of the orbit
    mkdir -p "$W/ncu-frames"
    timeout 400 "$ncu" --kernel-name regex:'[Pp]ixel' --launch-skip 9 --launch-count 1 --import-source yes \
      --section SpeedOfLight --section Occupancy --section WarpStateStats --section LaunchStats --section MemoryWorkloadAnalysis \
      --section MemoryWorkloadAnalysis_Tables --section ComputeWorkloadAnalysis --section InstructionStats --section SourceCounters \
      -o "$W/prof" -f "$BIN/$pb" "$forest" --device cuda --size 1920x1080 --frames 10 \
      --camera "$camera" -o "$W/ncu-frames/f_%04d.exr" > "$O/ncu_play_run.txt" 2>&1 || fail "ncu on $pb (see ncu_play_run.txt)"
    if [[ -f $W/prof.ncu-rep ]]; then
      "$ncu" -i "$W/prof.ncu-rep" --page details > "$O/ncu_play.txt" 2>&1
      "$ncu" -i "$W/prof.ncu-rep" --page source --csv --print-source cuda,sass > "$W/source-both.csv" 2>&1 || echo "no cuda,sass source page (build with -lineinfo)"
      grep -E "Duration|Active Threads|Warp Cycles Per Issued|Issued Instructions  |Registers Per|L1/TEX Hit|L2 Hit|Achieved Occ|Local Memory" "$O/ncu_play.txt"
      python3 bench/play/ncu_lines.py "$W/source-both.csv" 30 > "$O/ncu_play_lines.txt" 2>&1 && head -40 "$O/ncu_play_lines.txt"
      tar cJf "$O/ncu_play.tar.xz" -C "$W" prof.ncu-rep source-both.csv
    fi
    cuobjdump=$(command -v cuobjdump || ls /usr/local/cuda/bin/cuobjdump 2>/dev/null || true)
    [[ -n $cuobjdump ]] && "$cuobjdump" -sass "$BIN/$pb" | xz > "$O/sass_$pb.txt.xz"
  fi
fi

echo "=== end $(date -u +%T), status $status"
exit $status
