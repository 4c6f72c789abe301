// Monochrome pixel formats: PFNC codes and unpacking to cv::Mat.
#include <cstring>

#include "sl/drivers/aravis_camera.h"

namespace sl::drivers {

namespace {

// PFNC / GigE Vision pixel format codes (Aravis 0.8 lacks the PFNC "p" ones).
constexpr std::uint32_t kMono8 = 0x01080001u;
constexpr std::uint32_t kMono10 = 0x01100003u;
constexpr std::uint32_t kMono10Packed = 0x010C0004u;  // GigE Vision: 2 pixels in 3 bytes
constexpr std::uint32_t kMono12 = 0x01100005u;
constexpr std::uint32_t kMono12Packed = 0x010C0006u;  // GigE Vision: 2 pixels in 3 bytes
constexpr std::uint32_t kMono16 = 0x01100007u;
constexpr std::uint32_t kMono10p = 0x010A0046u;  // PFNC: LSB-first bit stream
constexpr std::uint32_t kMono12p = 0x010C0047u;  // PFNC: LSB-first bit stream

std::size_t bytesNeeded(std::uint32_t format, std::size_t pixels) {
  switch (format) {
    case kMono8: return pixels;
    case kMono10: case kMono12: case kMono16: return 2 * pixels;
    case kMono10Packed: case kMono12Packed: return (pixels * 3 + 1) / 2;
    case kMono10p: return (pixels * 10 + 7) / 8;
    case kMono12p: return (pixels * 12 + 7) / 8;
    default: return 0;
  }
}

// GigE Vision MonoNPacked: byte 0 = P0 high bits, byte 2 = P1 high bits,
// byte 1 = P0 low bits (bits 0..) and P1 low bits (bits 4..).
void unpackGigEPacked(const std::uint8_t* in, std::uint16_t* out, std::size_t pixels,
                      int bits) {
  const int low = bits - 8;
  const std::uint8_t mask = static_cast<std::uint8_t>((1u << low) - 1);
  std::size_t i = 0;
  for (; i + 1 < pixels; i += 2, in += 3) {
    out[i] = static_cast<std::uint16_t>((in[0] << low) | (in[1] & mask));
    out[i + 1] = static_cast<std::uint16_t>((in[2] << low) | ((in[1] >> 4) & mask));
  }
  if (i < pixels) out[i] = static_cast<std::uint16_t>((in[0] << low) | (in[1] & mask));
}

// PFNC MonoNp: pixel i occupies bits [N i, N i + N) of a little-endian bit stream.
void unpackLsbBitStream(const std::uint8_t* in, std::size_t size, std::uint16_t* out,
                        std::size_t pixels, int bits) {
  const std::uint32_t mask = (1u << bits) - 1;
  for (std::size_t i = 0; i < pixels; ++i) {
    const std::size_t bit = i * static_cast<std::size_t>(bits);
    const std::size_t byte = bit / 8;
    std::uint32_t word = in[byte];
    if (byte + 1 < size) word |= std::uint32_t(in[byte + 1]) << 8;
    if (byte + 2 < size) word |= std::uint32_t(in[byte + 2]) << 16;
    out[i] = static_cast<std::uint16_t>((word >> (bit % 8)) & mask);
  }
}

}  // namespace

int monoBitDepth(std::uint32_t format) {
  switch (format) {
    case kMono8: return 8;
    case kMono10: case kMono10Packed: case kMono10p: return 10;
    case kMono12: case kMono12Packed: case kMono12p: return 12;
    case kMono16: return 16;
    default: return 0;
  }
}

std::uint32_t monoPixelFormatCode(const std::string& name) {
  if (name == "Mono8") return kMono8;
  if (name == "Mono10") return kMono10;
  if (name == "Mono10Packed") return kMono10Packed;
  if (name == "Mono10p") return kMono10p;
  if (name == "Mono12") return kMono12;
  if (name == "Mono12Packed") return kMono12Packed;
  if (name == "Mono12p") return kMono12p;
  if (name == "Mono16") return kMono16;
  return 0;
}

cv::Mat decodeMonoImage(const void* data, std::size_t size, int width, int height,
                        std::uint32_t format) {
  if (width <= 0 || height <= 0 || data == nullptr) return {};
  const std::size_t pixels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  const std::size_t needed = bytesNeeded(format, pixels);
  if (needed == 0 || size < needed) return {};
  const auto* in = static_cast<const std::uint8_t*>(data);
  if (format == kMono8) {
    cv::Mat image(height, width, CV_8UC1);
    std::memcpy(image.data, in, pixels);
    return image;
  }
  cv::Mat image(height, width, CV_16UC1);
  auto* out = reinterpret_cast<std::uint16_t*>(image.data);
  switch (format) {
    case kMono10: case kMono12: case kMono16:  // little endian on the wire
      for (std::size_t i = 0; i < pixels; ++i)
        out[i] = static_cast<std::uint16_t>(in[2 * i] | (in[2 * i + 1] << 8));
      break;
    case kMono10Packed: unpackGigEPacked(in, out, pixels, 10); break;
    case kMono12Packed: unpackGigEPacked(in, out, pixels, 12); break;
    case kMono10p: unpackLsbBitStream(in, size, out, pixels, 10); break;
    case kMono12p: unpackLsbBitStream(in, size, out, pixels, 12); break;
    default: return {};
  }
  return image;
}

}  // namespace sl::drivers
