// image_diff.cpp: bench-image-diff, the image difference of two frames that canopy-play wrote as
// EXR (premultiplied linear RGBA): RMS over RGBA, and relative to the mean RGB of the reference's
// covered pixels (bench/play/image_error.h, as bench-play and bench-stereo report it). For
// comparing two builds, or a quality dial against the default, on the same camera.
//
//   bench-image-diff GOT.exr REFERENCE.exr [--json]
#include <cstdio>
#include <string>
#include <vector>

#include "bench/play/image_error.h"
#include "canopy/cli.h"
#include "canopy/errors.h"
#include "runtime/image_io.h"

int main(int argc, char** argv) {
  canopy::Tool tool("bench-image-diff", "RMS difference of two canopy-play EXR frames (over RGBA; relative to the reference's covered mean RGB)");
  std::string got, ref;
  tool.app().add_option("got", got, "GOT.exr")->required();
  tool.app().add_option("reference", ref, "REFERENCE.exr")->required();
  return tool.run(argc, argv, [&] {
    int w0 = 0, h0 = 0, w1 = 0, h1 = 0;
    const std::vector<float> a = canopy::play::readExrRgba(got, w0, h0), b = canopy::play::readExrRgba(ref, w1, h1);
    if (w0 != w1 || h0 != h1)
      throw canopy::invalidInput(got + ": " + std::to_string(w0) + "x" + std::to_string(h0) + ", the reference " + ref + " is " +
                                 std::to_string(w1) + "x" + std::to_string(h1));
    const canopy::play::bench::ImageError e = canopy::play::bench::imageError(a, b);
    if (!tool.common().json)  // stdout holds the report alone under --json
      std::printf("%s vs %s: RMS %.6g (%.3f %% of the covered mean RGB)\n", got.c_str(), ref.c_str(), e.rms, 100.0 * e.relative);
    tool.report() = {{"got", got}, {"reference", ref}, {"rms", e.rms}, {"relative", e.relative}, {"size", {w0, h0}}};
  });
}
