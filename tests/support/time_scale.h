// Upper bounds on wall-clock time in tests, scaled for sanitizer builds
// (SL_SANITIZE, which defines SL_SANITIZER_BUILD): ASan/UBSan runs the
// pipeline 2-4x slower, TSan 5-15x, so a bound that holds in a release build
// would fail there for no bug. Lower bounds (a delay was honoured) stay as
// they are.
#pragma once

#include <chrono>

namespace sl::test {

#ifdef SL_SANITIZER_BUILD
inline constexpr int kTimeScale = 10;
#else
inline constexpr int kTimeScale = 1;
#endif

template <typename Rep, typename Period>
constexpr auto scaledBound(std::chrono::duration<Rep, Period> d) {
  return d * kTimeScale;
}

}  // namespace sl::test
