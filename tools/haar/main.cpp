// canopy-haar: Haar-wavelet brick compression of LB light fields (see docs/haar.md).
//   canopy-haar IN.light.vdb -o OUT.chaar [--threshold T | --max-error E] [--precision fp16|fp32|quant]
//   canopy-haar decode IN.chaar -o OUT.vdb
//   canopy-haar info IN.chaar
//   canopy-haar verify IN.chaar
//   canopy-haar sweep IN.light.vdb --thresholds 0,0.001,0.01 -o PREFIX
#include <cmath>
#include <iostream>
#include <sstream>

#include "canopy/cli.h"
#include "haar.h"

namespace {
std::vector<float> parseList(const std::string& s) {
  std::vector<float> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) {
    try {
      size_t used = 0;
      const float v = std::stof(item, &used);
      if (used != item.size()) throw std::invalid_argument(item);
      out.push_back(v);
    } catch (const std::exception&) {
      throw canopy::usageError("--thresholds: '" + item + "' is not a number");
    }
  }
  return out;
}
}  // namespace

int main(int argc, char** argv) {
  using namespace canopy::haar;
  canopy::Tool tool("canopy-haar",
                    "Compresses an lbsolve light field (19 Vec3 grids B00..B18) into a .chaar file of "
                    "Haar-wavelet bricks with random-access trilinear decoding, and inspects such files.",
                    /*withDevice=*/false);
  CLI::App& app = tool.app();
  app.fallthrough();  // --json / --quiet also after a subcommand
  app.require_subcommand(0, 1);

  CompressOptions co;
  std::string precision = precisionName(co.precision);
  app.add_option("input", co.input, "lbsolve output (.light.vdb)");
  app.add_option("-o,--output", co.output, "output .chaar file");
  auto* thr = app.add_option("--threshold", co.threshold,
                             "drop detail coefficients whose R, G and B magnitudes are all <= T (default 0: every "
                             "coefficient kept, lossless with --precision fp32); with --precision quant, T is the "
                             "quantisation step (> 0)");
  auto* me = app.add_option("--max-error", co.maxError,
                            "instead of --threshold: per base, the largest threshold whose max absolute error "
                            "(measured, every texel) is <= E");
  thr->excludes(me);
  app.add_option("--precision", precision,
                 "coefficients: fp16 (half fp32's bytes; --max-error still holds, fp16 rounding measured), fp32 "
                 "(lossless at threshold 0), or quant (integers in steps of T, sqrt(2) T per fine-detail axis, on "
                 "G, R-G, B-G; the smallest files, .chaar 2.x; needs T > 0 or --max-error; canopy-octreepack "
                 "packs it with --no-haar-light only)")
      ->capture_default_str();

  std::string decIn, decOut;
  CLI::App* dec = app.add_subcommand("decode", "Decode a .chaar back to an OpenVDB file (B00..B18)");
  dec->add_option("input", decIn, "input .chaar")->required();
  dec->add_option("-o,--output", decOut, "output .vdb")->required();

  std::string infoIn;
  CLI::App* info = app.add_subcommand("info", "Print a .chaar's header and per-base statistics");
  info->add_option("input", infoIn, "input .chaar")->required();

  std::string verIn;
  CLI::App* ver = app.add_subcommand("verify", "Check a .chaar (checksums, indices, decodable); non-zero exit on any problem");
  ver->add_option("input", verIn, "input .chaar")->required();

  SweepOptions so;
  std::string sweepList = "0,0.001,0.003,0.01,0.03", sweepPrecision = precisionName(so.precision);
  CLI::App* sw = app.add_subcommand("sweep", "Compress at several thresholds; write PREFIX.csv, PREFIX.json, PREFIX.png");
  sw->add_option("input", so.input, "lbsolve output (.light.vdb)")->required();
  sw->add_option("--thresholds", sweepList, "comma-separated thresholds")->capture_default_str();
  sw->add_option("-o,--output", so.prefix, "output prefix")->required();
  sw->add_option("--precision", sweepPrecision, "coefficients: fp32, fp16 or quant (as for compression)")->capture_default_str();

  return tool.run(argc, argv, [&] {
    if (*dec) {
      tool.report() = decodeToVdb(decIn, decOut);
    } else if (*info) {  // the report is the requested output: stdout, also under --quiet
      tool.report() = chaarInfo(infoIn);
      if (!tool.common().json) std::cout << formatChaarInfo(tool.report());
    } else if (*ver) {
      tool.report() = verifyChaar(verIn);
      if (!tool.common().json) std::cout << formatVerify(tool.report());
    } else if (*sw) {
      so.thresholds = parseList(sweepList);
      so.precision = parsePrecision(sweepPrecision);
      tool.report() = sweepThresholds(so);
    } else {
      if (co.input.empty()) throw canopy::usageError("an input .light.vdb is required");
      if (co.output.empty()) throw canopy::usageError("-o OUT.chaar is required");
      if (*me && !(co.maxError >= 0 && std::isfinite(co.maxError)))
        throw canopy::usageError("--max-error must be a finite number >= 0");
      if (!(co.threshold >= 0 && std::isfinite(co.threshold)))
        throw canopy::usageError("--threshold must be a finite number >= 0");
      if (!*me) co.maxError = -1;
      co.precision = parsePrecision(precision);
      tool.report() = compressLight(co);
    }
  });
}
