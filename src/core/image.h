// PNG images: 8-bit grey/RGB and 16-bit grey (depth in millimetres), as Open3D's RGB-D tools and
// image viewers read them.
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

namespace twinforge::core {

struct Image {
  int width = 0, height = 0, channels = 0, bit_depth = 8;
  std::vector<uint8_t> bytes;  // row-major; 16-bit samples are stored native-endian
};

// Writes `image` as PNG (via a temp file and rename). Throws IoError naming the path.
void WritePng(const std::filesystem::path& path, const Image& image);

// Reads a PNG (8-bit grey/RGB/RGBA or 16-bit grey). Throws IoError naming the path.
Image ReadPng(const std::filesystem::path& path);

}  // namespace twinforge::core
