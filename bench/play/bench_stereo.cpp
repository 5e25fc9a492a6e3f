// bench_stereo.cpp: the second eye of a stereo pair by reprojection against the same eye traced in
// full, on a packed scene along a camera path, in one run:
//   - frame times: the traced (left) eye and the second eye, reprojected (reprojection + traced
//     holes) and traced in full, each the median over the frames; the ratio of the two second-eye
//     times is the figure of merit (the cost of the right eye with reprojection, as a fraction of a
//     full second render);
//   - the fraction of the second eye's pixels traced;
//   - image error: at a few frames of the path (converged, every page resident), the reprojected
//     right eye against the traced one: RMS over premultiplied RGBA, and that RMS over the mean RGB
//     of the traced eye's covered pixels (alpha > 0.5).
//
//   bench-stereo SCENE.canopy --camera PATH.json|orbit:... [--device cuda] [--size 1920x1080]
//                [--frames 120] [--ipd 0.064] [--cache-mb 1024] [--error-frames 0,40,80] [--json]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench/play/image_error.h"
#include "canopy/cli.h"
#include "runtime/image_io.h"
#include "runtime/player.h"

namespace pl = canopy::play;

using canopy::play::bench::ImageError;
using canopy::play::bench::imageError;

int main(int argc, char** argv) {
  canopy::Tool tool("bench-stereo", "Stereo by reprojection against a fully traced second eye: frame times, traced fraction, image error");
  CLI::App& app = tool.app();
  pl::PlayOptions o;
  std::string size = "1920x1080", errorFrames = "0,40,80", pngPrefix;
  o.frames = 120;
  o.stereoIpd = 0.064f;
  o.sun = "orbit:azimuth=40,elevation=45,turns=0.1";
  app.add_option("input", o.input, "SCENE.canopy")->required();
  app.add_option("--camera", o.camera, "Camera path (canopy-play --camera)")->required();
  app.add_option("--sun", o.sun, "Sun (canopy-play --sun)")->capture_default_str();
  app.add_option("--size", size, "Frame size")->capture_default_str();
  app.add_option("--frames", o.frames, "Frames timed")->capture_default_str();
  app.add_option("--ipd", o.stereoIpd, "Eye separation (scene units)")->capture_default_str();
  app.add_option("--stereo-spread", o.stereo.maxSpread, "canopy-play --stereo-spread")->capture_default_str();
  app.add_option("--stereo-solid", o.stereo.solidAlpha, "canopy-play --stereo-solid")->capture_default_str();
  app.add_option("--stereo-holes", o.stereoHoleOrder, "canopy-play --stereo-holes (CUDA: tile or kind)")->capture_default_str();
  app.add_option("--cache-mb", o.cacheMb, "Cache budget (MiB)")->capture_default_str();
  app.add_option("--shadows", o.shadowMethod, "map or cone")->capture_default_str();
  app.add_option("--error-frames", errorFrames, "Frames of the path where the image error is measured (converged)")->capture_default_str();
  app.add_option("--png", pngPrefix, "Write PREFIX-{left,right,traced}.png of the first error frame");
  return tool.run(argc, argv, [&] {
    if (std::sscanf(size.c_str(), "%dx%d", &o.width, &o.height) != 2) throw canopy::usageError("--size WxH");
    const canopy::Device device = tool.device();
    nlohmann::json report;
    // Timings: the real-time path (a complete first frame, then one pass per frame).
    for (const char* fill : {"reproject", "trace"}) {
      pl::PlayOptions t = o;
      t.stereoFill = fill;
      report[fill] = pl::play(t, device);
    }
    const auto& rp = report["reproject"]["stereo"];
    const auto& tr = report["trace"]["stereo"];
    const double second = rp["second_eye_ms_median"], full = tr["second_eye_ms_median"];
    // Image error at the chosen frames, converged.
    std::vector<double> rmsAll, relAll;
    std::stringstream ss(errorFrames);
    std::string item;
    bool first = true;
    while (std::getline(ss, item, ',')) {
      const int f = std::stoi(item);
      if (f < 0 || f >= o.frames) throw canopy::usageError("--error-frames: " + item + " is not a frame of the path");
      pl::PlayOptions e = o;
      e.frames = f + 1;  // keyframed cameras put frame f at the same pose whatever the frame count
      e.converge = true;
      std::vector<float> left, right, leftRef, rightRef;
      e.stereoFill = "reproject";
      pl::play(e, device, &left, &right);
      e.stereoFill = "trace";
      pl::play(e, device, &leftRef, &rightRef);
      const ImageError err = imageError(right, rightRef);
      rmsAll.push_back(err.rms);
      relAll.push_back(err.relative);
      report["error_frames"].push_back({{"frame", f}, {"rms", err.rms}, {"relative", err.relative}});
      if (first && !pngPrefix.empty()) {
        pl::writePng(pngPrefix + "-left.png", left, o.width, o.height, o.background);
        pl::writePng(pngPrefix + "-right.png", right, o.width, o.height, o.background);
        pl::writePng(pngPrefix + "-traced.png", rightRef, o.width, o.height, o.background);
      }
      first = false;
    }
    double rmsMean = 0.0, relMean = 0.0;
    for (size_t i = 0; i < rmsAll.size(); ++i) rmsMean += rmsAll[i] / double(rmsAll.size()), relMean += relAll[i] / double(relAll.size());
    std::printf("| scene | device | size | frames | ipd | first eye ms | second eye ms (reprojected) | second eye ms (traced) | "
                "reprojected / traced | pixels traced | pixels traced behind a front | RMS vs traced (error frames) | relative |\n"
                "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    std::printf("| %s | %s | %dx%d | %d | %g | %.2f | %.2f | %.2f | %.3f | %.1f%% | %.1f%% | %.4g | %.2f%% |\n", o.input.c_str(),
                std::string(report["reproject"]["device"]).c_str(), o.width, o.height, o.frames, double(o.stereoIpd),
                double(rp["first_eye_ms_median"]), second, full, full > 0 ? second / full : 0.0, 100.0 * double(rp["traced_fraction_mean"]),
                100.0 * double(rp["traced_behind_fraction_mean"]), rmsMean, 100.0 * relMean);
    report["second_eye_reprojected_over_traced"] = full > 0 ? second / full : 0.0;
    report["rms_mean"] = rmsMean;
    report["relative_rms_mean"] = relMean;
    tool.report() = report;
  });
}
