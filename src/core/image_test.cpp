#include "core/image.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>

#include "core/error.h"

namespace twinforge::core {
namespace {

TEST(Image, RgbAnd16BitDepthRoundTrip) {
  const auto dir = std::filesystem::temp_directory_path() / "twinforge_image_test";
  Image rgb{4, 3, 3, 8, {}};
  for (int i = 0; i < 4 * 3 * 3; ++i) rgb.bytes.push_back(static_cast<uint8_t>(i * 7));
  WritePng(dir / "rgb.png", rgb);
  const Image back = ReadPng(dir / "rgb.png");
  EXPECT_EQ(back.bytes, rgb.bytes);
  EXPECT_EQ(back.channels, 3);

  Image depth{3, 2, 1, 16, std::vector<uint8_t>(3 * 2 * 2)};
  const uint16_t mm[6] = {0, 1, 650, 1200, 40000, 65535};
  std::memcpy(depth.bytes.data(), mm, sizeof mm);
  WritePng(dir / "depth.png", depth);
  const Image depth_back = ReadPng(dir / "depth.png");
  ASSERT_EQ(depth_back.bit_depth, 16);
  uint16_t read[6];
  std::memcpy(read, depth_back.bytes.data(), sizeof read);
  for (int i = 0; i < 6; ++i) EXPECT_EQ(read[i], mm[i]);
}

TEST(Image, GarbageIsAClearError) {
  const auto path = std::filesystem::temp_directory_path() / "twinforge_not_a.png";
  std::ofstream(path) << "nope";
  EXPECT_THROW(ReadPng(path), IoError);
  EXPECT_THROW(WritePng("/proc/forbidden/x.png", Image{1, 1, 1, 8, {0}}), IoError);
}

}  // namespace
}  // namespace twinforge::core
