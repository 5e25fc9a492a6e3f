#!/usr/bin/env bash
# variant.sh NAME "EXTRA NVCC FLAGS" [DROP]: builds canopy-play and bench-play with runtime/render_cuda.cu
# compiled with extra nvcc flags (e.g. -lineinfo for Nsight Compute's source page, or
# --use_fast_math for an A/B), as build/bin/{canopy-play,bench-play,bench-stereo,test_play_cuda}-NAME, from
# the objects of an up-to-date Ninja build in build/ (the build's own binaries are not touched).
# DROP: a flag of the build's command line to leave out (e.g. --use_fast_math, for the IEEE build).
# PREINC=DIR (environment): DIR is searched for includes before the project's own directories, e.g.
# an earlier commit's runtime/cone.h for an A/B of the kernel (`git show REV:runtime/cone.h`).
# SRC=FILE (environment): FILE is compiled instead of runtime/render_cuda.cu (an edited copy, e.g. another
# launch bound), with the project's include paths.
set -euo pipefail
name=$1 flags=$2 drop=${3:-}
cd "$(dirname "$0")/../../build"
ninja canopy-play bench-play bench-stereo test_play_cuda > /dev/null
w=$(mktemp -d)
obj=runtime/CMakeFiles/canopy_runtime.dir/render_cuda.cu.o
compile=$(ninja -t commands bin/canopy-play | grep -F -- "-o $obj" | tail -1)
compile=${compile/-o $obj/-o $w/render_cuda.cu.o $flags}
compile=$(sed 's| -MD -MT [^ ]* -MF [^ ]*||' <<< "$compile")
[[ -z $drop ]] || compile=${compile// $drop / }
[[ -z ${PREINC:-} ]] || compile=$(sed "s|^\([^ ]*nvcc\) |\1 -I$PREINC |" <<< "$compile")
[[ -z ${SRC:-} ]] || compile=$(sed "s| [^ ]*/runtime/render_cuda.cu | $(realpath "$SRC") |" <<< "$compile")
eval "$compile"
cp runtime/libcanopy_runtime.a "$w/"
(cd "$w" && ar r libcanopy_runtime.a render_cuda.cu.o)
for b in canopy-play bench-play bench-stereo test_play_cuda; do
  link=$(ninja -t commands "bin/$b" | tail -1)
  link=${link//runtime\/libcanopy_runtime.a/$w\/libcanopy_runtime.a}
  link=${link/-o bin\/$b /-o bin\/$b-$name }
  eval "$link"
done
rm -rf "$w"
echo "built build/bin/{canopy-play,bench-play,bench-stereo,test_play_cuda}-$name ($flags)"
