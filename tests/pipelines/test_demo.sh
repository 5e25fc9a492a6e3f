#!/usr/bin/env bash
# The demo through make, from a clean state: every intermediate checked by the tools' own
# info/verify, the PNG's size and that it is not blank; nothing rebuilt when nothing changed; only
# the dependent targets rebuilt after a touch; a build killed with SIGKILL recovers; two builds
# give identical bytes.   usage: test_demo.sh BIN SOURCE_DIR
set -euo pipefail
BIN=$1 SRC=$2
here=$(cd "$(dirname "$0")" && pwd)
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
run_make() {  # run_make OUT [make args...]
  local out=$1; shift
  make --no-print-directory -C "$SRC/pipelines" BIN="$BIN" O="$out" RESOLUTION=24 DEVICE=cpu PLAY_SIZE=160x120 "$@"
}
check_all() {
  local d=$1
  "$BIN/canopy-voxelize" info "$d/sample.density.vdb" > /dev/null
  "$BIN/canopy-lbsolve" info "$d/sample.light.vdb" > /dev/null
  "$BIN/canopy-haar" verify "$d/sample.light.chaar" > /dev/null
  "$BIN/canopy-octreepack" verify "$d/sample.canopy" > /dev/null
  python3 "$here/png_check.py" "$d/sample.png" 160 120
}
tools_run() { { grep -oE "bin/canopy-[a-z]+" || true; } | sed 's|bin/||' | sort | tr '\n' ' '; }

echo "== clean build"
run_make "$T/a" demo
D=$T/a/demo
check_all "$D"

echo "== nothing to do when nothing changed"
ran=$(run_make "$T/a" -n demo | tools_run)
[[ -z $ran ]] || { echo "FAIL: an up-to-date build would run: $ran"; exit 1; }

echo "== touching the light file rebuilds only what depends on it"
sleep 1; touch "$D/sample.light.vdb"
ran=$(run_make "$T/a" -n demo | tools_run)
[[ $ran == "canopy-haar canopy-octreepack canopy-play " ]] || { echo "FAIL: after touching sample.light.vdb make would run: '$ran'"; exit 1; }
run_make "$T/a" demo > /dev/null
sleep 1; touch "$D/sample.glb"
ran=$(run_make "$T/a" -n demo | tools_run)
[[ $ran == "canopy-haar canopy-lbsolve canopy-octreepack canopy-play canopy-voxelize " ]] || { echo "FAIL: after touching sample.glb make would run: '$ran'"; exit 1; }

echo "== a build killed mid-way (SIGKILL) leaves no half-written target and the next make finishes it"
killed=0
for delay in 0.3 0.8 1.5; do
  sleep 1; touch "$D/sample.glb"
  setsid bash -c "exec make --no-print-directory -C '$SRC/pipelines' BIN='$BIN' O='$T/a' RESOLUTION=24 DEVICE=cpu PLAY_SIZE=160x120 demo" > "$T/killed.log" 2>&1 &
  pid=$!
  sleep "$delay"
  if kill -0 "$pid" 2>/dev/null; then kill -9 -- "-$pid" 2>/dev/null || true; killed=$((killed + 1)); fi
  wait "$pid" 2>/dev/null || true
  # Whatever exists is whole: every target present must pass its tool's check.
  [[ ! -e $D/sample.density.vdb ]] || "$BIN/canopy-voxelize" info "$D/sample.density.vdb" > /dev/null
  [[ ! -e $D/sample.light.vdb ]] || "$BIN/canopy-lbsolve" info "$D/sample.light.vdb" > /dev/null
  [[ ! -e $D/sample.light.chaar ]] || "$BIN/canopy-haar" verify "$D/sample.light.chaar" > /dev/null
  [[ ! -e $D/sample.canopy ]] || "$BIN/canopy-octreepack" verify "$D/sample.canopy" > /dev/null
  run_make "$T/a" demo > /dev/null
  check_all "$D" > /dev/null
done
((killed > 0)) || { echo "FAIL: no build was still running when killed"; exit 1; }
echo "killed $killed build(s) mid-way; each recovered"
# A tool killed by SIGKILL cannot remove its temporary (.NAME.canopy-tmp.XXXXXX, never a target's
# name, so make never takes it for one); the check of temporaries below is about the refused runs.
rm -f "$D"/.*.canopy-tmp.*

echo "== an output path naming the run's own input is refused (exit 1) and the input is left as it was"
refused() {  # refused INPUT TOOL ARGS...: the tool must exit 1, say so on one line, leave INPUT's bytes
  local in=$1; shift
  local before; before=$(sha256sum "$in")
  local rc=0; "$@" -q 2> "$T/refused.err" || rc=$?
  [[ $rc == 1 ]] || { echo "FAIL: '$*' exited $rc, expected 1"; cat "$T/refused.err"; exit 1; }
  grep -q "output path is the same file as an input" "$T/refused.err" || { echo "FAIL: '$*' said:"; cat "$T/refused.err"; exit 1; }
  [[ $(wc -l < "$T/refused.err") == 1 ]] || { echo "FAIL: '$*' printed more than one line"; cat "$T/refused.err"; exit 1; }
  [[ $(sha256sum "$in") == "$before" ]] || { echo "FAIL: '$*' changed $in"; exit 1; }
}
refused "$D/sample.glb" "$BIN/canopy-voxelize" -r 24 "$D/sample.glb" -o "$D/sample.glb"
refused "$D/sample.density.vdb" "$BIN/canopy-lbsolve" --device cpu "$D/sample.density.vdb" -o "$D/./sample.density.vdb"
refused "$D/sample.light.vdb" "$BIN/canopy-haar" "$D/sample.light.vdb" -o "$D/sample.light.vdb"
ln -sf sample.light.chaar "$D/alias.chaar"  # through a symbolic link too
refused "$D/sample.light.chaar" "$BIN/canopy-octreepack" "$D/sample.density.vdb" "$D/sample.light.chaar" -o "$D/alias.chaar"
rm "$D/alias.chaar"
cp "$D/sample.canopy" "$T/packed.png"  # canopy-play writes only .png/.exr; the file, not its name, is read
refused "$T/packed.png" "$BIN/canopy-play" --device cpu --size 16x16 "$T/packed.png" -o "$T/packed.png"
rm "$T/packed.png"
if ls -A "$D" | grep -q canopy-tmp; then echo "FAIL: temporaries left in $D"; ls -la "$D"; exit 1; fi
check_all "$D" > /dev/null

echo "== two clean builds give identical bytes"
run_make "$T/b" demo > /dev/null
for f in sample.glb sample.density.vdb sample.light.vdb sample.light.chaar sample.canopy sample.png; do
  cmp "$T/a/demo/$f" "$T/b/demo/$f"
done
echo "PASS"
