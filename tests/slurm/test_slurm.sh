#!/usr/bin/env bash
# The plant library on a throwaway single-node Slurm (pipelines/slurm/local-cluster):
#  1. a local `make library` is the reference;
#  2. `make -j library LAUNCH='srun ...'` runs every tool as a job step: same bytes; the GPU flags go
#     to lbsolve's steps only;
#  3. `pipelines/slurm/submit-library --wait`: a job array (one task per plant) and the index job
#     after it: same bytes; `--dry-run` prints the two sbatch commands;
#  4. a corrupt plant among good ones, through srun and through submit-library: only its target
#     fails, the others complete and match, make's exit code is non-zero, nothing of the bad plant
#     is left behind, and the index job is cancelled;
#  5. the daemons are stopped by their process ids, on failure too.
# usage: test_slurm.sh BIN SOURCE_DIR PLANTS_DIR      (root, slurm-wlm and munge needed: else exit 77)
set -euo pipefail
BIN=$1 SRC=$2 PLANTS=$3
skip() {
  if [[ ${CANOPY_REQUIRE_SLURM:-0} == 1 ]]; then echo "FAIL: $*"; exit 1; fi
  echo "SKIP: $*"; exit 77
}
((EUID == 0)) || skip "needs root (slurmd starts job steps as any user)"
for t in munged slurmctld slurmd srun sbatch scontrol sinfo; do
  command -v "$t" > /dev/null || skip "$t not installed (apt-get install slurm-wlm munge)"
done

T=$(mktemp -d /tmp/canopy-slurm.XXXXXX)
C=$T/cluster
cleanup() {
  local rc=$?
  "$SRC/pipelines/slurm/local-cluster" stop "$C" || true
  if ((rc != 0)); then
    for f in "$C"/slurmctld.log "$C"/slurmd.log "$T"/sub*/slurm/*.log; do
      [[ -f $f ]] && { echo "--- $f (tail)"; tail -n 15 "$f"; }
    done
  fi
  rm -rf "$T"
}
trap cleanup EXIT
fail() { echo "FAIL: $*"; exit 1; }
VARS=(RESOLUTION=24 SUPERSAMPLE=4 DEVICE=cpu)
mk() { make --no-print-directory -C "$SRC/pipelines" BIN="$BIN" "${VARS[@]}" "$@"; }
same_outputs() {  # same_outputs REF DIR: every file of the reference build is in DIR, byte for byte
  local ref=$1 dir=$2 f n=0
  for f in "$ref"/*; do
    [[ -f $f ]] || continue
    cmp -s "$f" "$dir/$(basename "$f")" || fail "$dir/$(basename "$f") differs from the local build (or is missing)"
    n=$((n + 1))
  done
  echo "   $n files byte-identical to the local build"
}
no_leftovers() {  # no_leftovers DIR NAME: no output and no temporary file of plant NAME
  local left
  left=$(cd "$1" && ls -A | grep -E "(^|\.)$2\." || true)
  [[ -z $left ]] || fail "the failed plant left files behind in $1: $left"
}

echo "== local reference build"
start=$(date +%s)
mk -j2 O="$T/local" PLANTS="$PLANTS" library > "$T/local.log" 2>&1 || { cat "$T/local.log"; fail "local build"; }
echo "   $(($(date +%s) - start)) s"
REF=$T/local/plants
nplants=$(python3 -c 'import json,sys; print(len(json.load(open(sys.argv[1]))["plants"]))' "$REF/library.json")
echo "   $nplants plants indexed"

echo "== cluster"
start=$(date +%s)
export CANOPY_SLURM_PORT=$((20000 + RANDOM % 20000))
eval "$("$SRC/pipelines/slurm/local-cluster" start "$C")"
echo "   up in $(($(date +%s) - start)) s (SLURM_CONF=$SLURM_CONF, port $CANOPY_SLURM_PORT)"
for p in munged slurmctld slurmd; do
  kill -0 "$(cat "$C/$p.pid")" || fail "$p is not running"
done

SRUN="srun -N1 -n1 --quiet"
echo "== the GPU request goes to the GPU tools' steps only"
mkdir -p "$T/plan/plants"
plan=$(mk -n O="$T/plan" PLANTS="$PLANTS" LAUNCH="$SRUN" plants)
grep -E "^$SRUN --gres=gpu:1 .*canopy-lbsolve " <<< "$plan" > /dev/null || fail "lbsolve step without --gres=gpu:1"
grep -E "^$SRUN .*canopy-voxelize " <<< "$plan" > /dev/null || fail "voxelize step not launched"
if grep -E "gres.*canopy-(voxelize|haar|octreepack) " <<< "$plan" > /dev/null; then fail "a CPU tool asks for a GPU"; fi

echo "== make -j2 library LAUNCH='$SRUN' (no GPUs on this node: GPU_LAUNCH_FLAGS=)"
start=$(date +%s)
mk -j2 O="$T/srun" PLANTS="$PLANTS" LAUNCH="$SRUN" GPU_LAUNCH_FLAGS= library > "$T/srun.log" 2>&1 ||
  { cat "$T/srun.log"; fail "make through srun"; }
echo "   $(($(date +%s) - start)) s"
same_outputs "$REF" "$T/srun/plants"

echo "== submit-library --dry-run"
dry=$("$SRC/pipelines/slurm/submit-library" "$PLANTS" -o "$T/dry" --bin "$BIN" --dry-run)
grep -q -- "--array=0-$((nplants - 1)) " <<< "$dry" || { echo "$dry"; fail "no job array of $nplants tasks"; }
grep -q -- "--gres=gpu:1" <<< "$dry" || fail "the plant tasks do not ask for a GPU by default"
grep -q -- "--dependency=afterok:" <<< "$dry" || fail "no dependent job"
[[ ! -e $T/dry ]] || fail "--dry-run wrote $T/dry"

echo "== submit-library --wait"
start=$(date +%s)
ids=$("$SRC/pipelines/slurm/submit-library" "$PLANTS" -o "$T/sub" --bin "$BIN" --make-flags "${VARS[*]}" \
  --gpu-flags '' --cpus-per-task 1 --wait) || fail "submit-library"
echo "$ids" | sed 's/^/   /'
grep -qE '^array [0-9]+$' <<< "$ids" && grep -qE '^final [0-9]+$' <<< "$ids" || fail "job ids not printed"
echo "   $(($(date +%s) - start)) s"
same_outputs "$REF" "$T/sub/plants"

echo "== a corrupt plant among good ones"
B=$T/bad-plants
mkdir -p "$B"
good=()
for m in "$PLANTS"/*.glb; do
  good+=("$(basename "${m%.*}")"); ln -s "$m" "$B/"
  ((${#good[@]} < 2)) || break
done
head -c 4000 "$PLANTS/$(basename "$(ls "$PLANTS"/*.glb | head -1)")" > "$B/broken.glb"  # truncated glTF
set +e
mk -k -j2 O="$T/bad-srun" PLANTS="$B" LAUNCH="$SRUN" GPU_LAUNCH_FLAGS= plants > "$T/bad-srun.log" 2>&1
rc=$?
set -e
((rc != 0)) || fail "make -k through srun exited 0 with a corrupt plant"
{ grep -E "error:" "$T/bad-srun.log" || true; } | sed 's/^/   /'
grep -q "broken.glb" "$T/bad-srun.log" || { cat "$T/bad-srun.log"; fail "the tool's error does not name broken.glb"; }
for g in "${good[@]}"; do cmp -s "$REF/$g.canopy" "$T/bad-srun/plants/$g.canopy" || fail "srun: good plant $g not built"; done
no_leftovers "$T/bad-srun/plants" broken
echo "   srun: make exit $rc, ${#good[@]} good plants built and identical, nothing of broken.glb left"

set +e
"$SRC/pipelines/slurm/submit-library" "$B" -o "$T/bad-sub" --bin "$BIN" --make-flags "${VARS[*]}" \
  --gpu-flags '' --cpus-per-task 1 --wait > "$T/bad-sub.out" 2> "$T/bad-sub.err"
rc=$?
set -e
((rc == 4)) || { cat "$T/bad-sub.err"; fail "submit-library --wait exited $rc with a corrupt plant (expected 4)"; }
grep -q "plant broken " "$T/bad-sub.err" || { cat "$T/bad-sub.err"; fail "the failed task is not named"; }
for g in "${good[@]}"; do cmp -s "$REF/$g.canopy" "$T/bad-sub/plants/$g.canopy" || fail "submit-library: good plant $g not built"; done
no_leftovers "$T/bad-sub/plants" broken
[[ ! -e $T/bad-sub/plants/library.json ]] || fail "the index was built although a plant failed"
grep -q "final .*CANCELLED" "$T/bad-sub.err" || { cat "$T/bad-sub.err"; fail "the index job was not cancelled"; }
echo "   submit-library: exit 4, the failed plant named, good plants built, index job cancelled"

echo "== stop"
pids=$(cat "$C"/munged.pid "$C"/slurmctld.pid "$C"/slurmd.pid)
"$SRC/pipelines/slurm/local-cluster" stop "$C"
for p in $pids; do ! kill -0 "$p" 2> /dev/null || fail "process $p still running after stop"; done
echo "PASS: local, srun and submit-library builds byte-identical; a corrupt plant fails alone"
