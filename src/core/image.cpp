#include "core/image.h"

#include <png.h>

#include <cstdio>
#include <cstring>
#include <memory>

#include "core/error.h"
#include "core/fs.h"

namespace twinforge::core {

namespace {
struct FileCloser {
  void operator()(std::FILE* f) const {
    if (f) std::fclose(f);
  }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

bool LittleEndian() {
  const uint16_t one = 1;
  uint8_t first;
  std::memcpy(&first, &one, 1);
  return first == 1;
}
}  // namespace

void WritePng(const std::filesystem::path& path, const Image& image) {
  const int sample = image.bit_depth / 8;
  if ((image.bit_depth != 8 && image.bit_depth != 16) || image.channels < 1 || image.channels > 4 ||
      image.bytes.size() !=
          static_cast<std::size_t>(image.width) * image.height * image.channels * sample)
    throw IoError("cannot write " + path.string() + ": image size, channels or depth invalid");
  EnsureDirectory(path.parent_path());
  const auto temp = std::filesystem::path(path.string() + ".tmp");
  FilePtr file(std::fopen(temp.c_str(), "wb"));
  if (!file) throw IoError("cannot write " + path.string() + ": " + std::strerror(errno));
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png_create_info_struct(png);
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    throw IoError("cannot write " + path.string() + ": libpng failed");
  }
  png_init_io(png, file.get());
  const int color = image.channels == 1   ? PNG_COLOR_TYPE_GRAY
                    : image.channels == 2 ? PNG_COLOR_TYPE_GRAY_ALPHA
                    : image.channels == 3 ? PNG_COLOR_TYPE_RGB
                                          : PNG_COLOR_TYPE_RGBA;
  png_set_IHDR(png, info, image.width, image.height, image.bit_depth, color, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_set_compression_level(png, 3);
  png_write_info(png, info);
  if (image.bit_depth == 16 && LittleEndian()) png_set_swap(png);
  const std::size_t stride = static_cast<std::size_t>(image.width) * image.channels * sample;
  for (int y = 0; y < image.height; ++y)
    png_write_row(png, const_cast<png_bytep>(image.bytes.data() + y * stride));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  file.reset();
  std::error_code ec;
  std::filesystem::rename(temp, path, ec);
  if (ec) throw IoError("cannot write " + path.string() + ": " + ec.message());
}

Image ReadPng(const std::filesystem::path& path) {
  FilePtr file(std::fopen(path.c_str(), "rb"));
  if (!file) throw IoError("cannot read " + path.string() + ": " + std::strerror(errno));
  png_byte header[8];
  if (std::fread(header, 1, 8, file.get()) != 8 || png_sig_cmp(header, 0, 8))
    throw IoError("cannot read " + path.string() + ": not a PNG file");
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png_create_info_struct(png);
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    throw IoError("cannot read " + path.string() + ": damaged PNG data");
  }
  png_init_io(png, file.get());
  png_set_sig_bytes(png, 8);
  png_read_info(png, info);
  Image image;
  image.width = static_cast<int>(png_get_image_width(png, info));
  image.height = static_cast<int>(png_get_image_height(png, info));
  image.bit_depth = png_get_bit_depth(png, info);
  if (png_get_color_type(png, info) == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (image.bit_depth < 8) png_set_expand(png), image.bit_depth = 8;
  if (image.bit_depth == 16 && LittleEndian()) png_set_swap(png);
  png_read_update_info(png, info);
  image.channels = png_get_channels(png, info);
  const std::size_t stride = png_get_rowbytes(png, info);
  image.bytes.resize(stride * image.height);
  for (int y = 0; y < image.height; ++y)
    png_read_row(png, image.bytes.data() + y * stride, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
  return image;
}

}  // namespace twinforge::core
