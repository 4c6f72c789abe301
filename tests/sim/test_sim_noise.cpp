// The simulator's noise source against its definition (sim_render.h): a
// splitmix64 stream, four table indices per hash. The fill is split into a
// hash loop and a table lookup that are compiled for several instruction
// sets; whichever variant this CPU runs must give the stream exactly.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <vector>

#include "sim/sim_render.h"

namespace {

using sl::drivers::sim::mix64;
using sl::drivers::sim::normalQuantile;
using sl::drivers::sim::NormalSource;

constexpr std::uint64_t kStep = 0x9e3779b97f4a7c15ull;  // splitmix64's increment

// The definition, one variate at a time.
struct ReferenceStream {
  explicit ReferenceStream(std::uint64_t seed) : state(mix64(seed + kStep)) {}
  std::vector<float> fill(int count) {
    std::vector<float> out;
    for (int i = 0; i < count; i += 4) {
      state += kStep;
      const std::uint64_t bits = mix64(state);
      for (int j = 0; j < 4 && i + j < count; ++j)
        out.push_back(normalQuantile(static_cast<std::uint16_t>(bits >> (16 * j))));
    }
    return out;
  }
  std::uint64_t state;
};

}  // namespace

TEST_CASE("NormalSource gives the splitmix64 stream of table quantiles, four per hash",
          "[sim][noise]") {
  for (const std::uint64_t seed : {0ull, 1ull, 0xdeadbeefcafef00dull}) {
    NormalSource source(seed);
    ReferenceStream reference(seed);
    // Row widths of real cameras and the odd lengths that end within a hash;
    // consecutive calls continue the stream.
    for (const int count : {1440, 1, 3, 4, 5, 7, 2048, 1441, 0, 2}) {
      std::vector<float> got(static_cast<std::size_t>(count) + 1, -99.0f);
      source.fill(got.data(), count);
      const std::vector<float> want = reference.fill(count);
      for (int i = 0; i < count; ++i) {
        INFO("seed " << seed << ", count " << count << ", variate " << i);
        REQUIRE(got[static_cast<std::size_t>(i)] == want[static_cast<std::size_t>(i)]);
      }
      REQUIRE(got[static_cast<std::size_t>(count)] == -99.0f);  // nothing written beyond
    }
  }
}

TEST_CASE("NormalSource's table is a unit normal", "[sim][noise]") {
  double sum = 0, sum_sq = 0;
  for (int i = 0; i < 65536; ++i) {
    const double v = normalQuantile(static_cast<std::uint16_t>(i));
    sum += v;
    sum_sq += v * v;
    if (i > 0) REQUIRE(v > normalQuantile(static_cast<std::uint16_t>(i - 1)));  // quantiles ascend
  }
  CHECK(std::abs(sum / 65536) < 1e-6);
  CHECK(sum_sq / 65536 == Approx(1.0).epsilon(1e-5));
  // The tails end at the quantile of 0.5 / 2^16: about 4.3 sigma.
  CHECK(normalQuantile(65535) == Approx(4.33).margin(0.02));
  CHECK(normalQuantile(0) == -normalQuantile(65535));
}
