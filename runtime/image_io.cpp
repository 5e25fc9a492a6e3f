// image_io.cpp: see image_io.h.
#include "runtime/image_io.h"

#include <png.h>

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <half.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <memory>

#include "canopy/atomic_file.h"
#include "canopy/errors.h"

namespace canopy::play {
namespace {

std::string lowerExt(const std::string& p) {
  const size_t dot = p.find_last_of('.');
  if (dot == std::string::npos) return "";
  std::string e = p.substr(dot);
  for (char& c : e) c = char(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

}  // namespace

float linearToSrgb(float v) {
  v = v < 0.0f ? 0.0f : (v > 1.0f ? 1.0f : v);
  return v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
}

bool isImageName(const std::string& path) {
  const std::string e = lowerExt(path);
  return e == ".png" || e == ".exr";
}

void writeExr(const std::string& path, const std::vector<float>& rgba, int width, int height) {
  AtomicOutput out(path);
  try {
    std::vector<half> px(size_t(width) * height * 4);
    for (size_t i = 0; i < px.size(); ++i) px[i] = half(rgba[i]);
    Imf::Header header(width, height);
    header.compression() = Imf::ZIP_COMPRESSION;
    const char* names[4] = {"R", "G", "B", "A"};
    for (const char* n : names) header.channels().insert(n, Imf::Channel(Imf::HALF));
    Imf::OutputFile file(out.tempPath().c_str(), header, 1);  // one thread: deterministic bytes
    Imf::FrameBuffer fb;
    for (int c = 0; c < 4; ++c)
      fb.insert(names[c], Imf::Slice(Imf::HALF, reinterpret_cast<char*>(px.data() + c), sizeof(half) * 4, sizeof(half) * 4 * width));
    file.setFrameBuffer(fb);
    file.writePixels(height);
  } catch (const std::exception& e) {
    throw ioError(path + ": cannot write EXR: " + e.what());
  }
  out.commit();
}

void writePng(const std::string& path, const std::vector<float>& rgba, int width, int height, const float bg[3]) {
  AtomicOutput out(path);
  std::vector<unsigned char> rows(size_t(width) * height * 3);
  for (size_t i = 0; i < size_t(width) * height; ++i) {
    const float T = 1.0f - rgba[4 * i + 3];
    for (int c = 0; c < 3; ++c)
      rows[3 * i + size_t(c)] = static_cast<unsigned char>(std::lround(255.0f * linearToSrgb(rgba[4 * i + size_t(c)] + T * bg[c])));
  }
  FILE* fp = std::fopen(out.tempPath().c_str(), "wb");
  if (!fp) throw ioError(path + ": cannot open for writing");
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    std::fclose(fp);
    throw ioError(path + ": cannot write PNG");
  }
  png_init_io(png, fp);
  png_set_IHDR(png, info, png_uint_32(width), png_uint_32(height), 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_set_sRGB(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
  png_write_info(png, info);
  for (int y = 0; y < height; ++y) png_write_row(png, rows.data() + size_t(y) * width * 3);
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  if (std::fclose(fp) != 0) throw ioError(path + ": cannot write PNG");
  out.commit();
}

void writeImage(const std::string& path, const std::vector<float>& rgba, int width, int height, const float bg[3]) {
  const std::string e = lowerExt(path);
  if (e == ".exr") return writeExr(path, rgba, width, height);
  if (e == ".png") return writePng(path, rgba, width, height, bg);
  throw usageError(path + ": output must end in .png or .exr");
}

std::vector<float> readExrRgba(const std::string& path, int& width, int& height) {
  try {
    Imf::InputFile file(path.c_str());
    const Imath::Box2i dw = file.header().dataWindow();
    width = dw.max.x - dw.min.x + 1;
    height = dw.max.y - dw.min.y + 1;
    std::vector<float> px(size_t(width) * height * 4, 0.0f);
    Imf::FrameBuffer fb;
    const char* names[4] = {"R", "G", "B", "A"};
    char* base = reinterpret_cast<char*>(px.data()) - (size_t(dw.min.x) + size_t(dw.min.y) * width) * sizeof(float) * 4;
    for (int c = 0; c < 4; ++c)
      fb.insert(names[c], Imf::Slice(Imf::FLOAT, base + c * sizeof(float), sizeof(float) * 4, sizeof(float) * 4 * width));
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    return px;
  } catch (const std::exception& e) {
    throw invalidInput(path + ": cannot read EXR: " + e.what());
  }
}

std::vector<unsigned char> readPngRgb(const std::string& path, int& width, int& height) {
  FILE* fp = std::fopen(path.c_str(), "rb");
  if (!fp) throw ioError(path + ": cannot open");
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info || setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    std::fclose(fp);
    throw invalidInput(path + ": not a readable PNG");
  }
  png_init_io(png, fp);
  png_read_info(png, info);
  width = int(png_get_image_width(png, info));
  height = int(png_get_image_height(png, info));
  png_set_strip_16(png);
  png_set_strip_alpha(png);
  png_set_palette_to_rgb(png);
  png_set_gray_to_rgb(png);
  png_read_update_info(png, info);
  std::vector<unsigned char> px(size_t(width) * height * 3);
  std::vector<png_bytep> rows(static_cast<size_t>(height));
  for (int y = 0; y < height; ++y) rows[size_t(y)] = px.data() + size_t(y) * width * 3;
  png_read_image(png, rows.data());
  png_destroy_read_struct(&png, &info, nullptr);
  std::fclose(fp);
  return px;
}

}  // namespace canopy::play
