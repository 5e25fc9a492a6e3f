// image_io.h: frame output. EXR: linear half RGBA, premultiplied RGB, alpha = 1 - transmittance
// (OpenEXR). PNG: 8-bit sRGB RGB of the frame composited over the background (libpng). Both are
// written atomically (temporary file + rename) and are deterministic for the same pixels.
#pragma once
#include <string>
#include <vector>

namespace canopy::play {

// rgba: width * height * 4 floats (premultiplied RGB, alpha), row 0 at the top.
void writeExr(const std::string& path, const std::vector<float>& rgba, int width, int height);
void writePng(const std::string& path, const std::vector<float>& rgba, int width, int height, const float background[3]);
// Writes by extension (.exr or .png); throws canopy::Error(Usage) for another extension.
void writeImage(const std::string& path, const std::vector<float>& rgba, int width, int height, const float background[3]);
// True for a name ending in .png or .exr (case-insensitive).
bool isImageName(const std::string& path);

// Reads an EXR back (tests): width * height RGBA floats.
std::vector<float> readExrRgba(const std::string& path, int& width, int& height);

// Reads an 8-bit PNG back (tests): width, height, RGB bytes.
std::vector<unsigned char> readPngRgb(const std::string& path, int& width, int& height);

// Linear -> sRGB-encoded value in [0, 1].
float linearToSrgb(float v);

}  // namespace canopy::play
