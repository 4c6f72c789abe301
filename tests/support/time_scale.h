// Upper bounds on wall-clock time in tests, scaled for sanitizer builds
// (SL_SANITIZE, which defines SL_SANITIZER_BUILD): ASan/UBSan runs the
// pipeline 2-4x slower, TSan 5-15x, so a bound that holds in a release build
// would fail there for no bug. Lower bounds (a delay was honoured) stay as
// they are.
#pragma once

#include <chrono>
#include <string>

namespace sl::test {

#ifdef SL_SANITIZER_BUILD
inline constexpr int kTimeScale = 10;
#else
inline constexpr int kTimeScale = 1;
#endif

// ThreadSanitizer builds (GCC's __SANITIZE_THREAD__, Clang's
// __has_feature(thread_sanitizer)): the slowest, where a simulated rig that
// runs in real time is also made smaller (tests/daemon/test_engine.cpp).
#if defined(__SANITIZE_THREAD__)
inline constexpr bool kThreadSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
inline constexpr bool kThreadSanitizer = true;
#else
inline constexpr bool kThreadSanitizer = false;
#endif
#else
inline constexpr bool kThreadSanitizer = false;
#endif

template <typename Rep, typename Period>
constexpr auto scaledBound(std::chrono::duration<Rep, Period> d) {
  return d * kTimeScale;
}

// The frame rate for a simulated camera that runs in real time (tests of the
// engine and the daemon): slowed by kTimeScale in sanitizer builds. Under
// TSan a live 1440 x 1080 frame takes ~130 ms to render, four frame
// intervals at 30 Hz: the simulator would lose most sequences for want of
// CPU, and the tests would measure the renderer, not the code under test.
constexpr double scaledCameraFps(double fps) { return fps / kTimeScale; }

// Appended to CYCLONEDDS_URI (after a comma) by the tests that use DDS: the
// participants' lease, Cyclone's 10 s by default, x kTimeScale. A process
// that does not run for longer than its lease (starved at nice 19 on a
// loaded machine, or stopped) is taken for gone by its peers, which delete
// its writers and readers and match them again when it resumes; a volatile
// reliable reader then misses what was written in between, and the writer
// counts it as acknowledged. In a sanitizer build that is the machine, not
// the code under test. Empty outside sanitizer builds.
inline std::string scaledDdsLeaseXml() {
  if (kTimeScale == 1) return "";
  return ",<Discovery><LeaseDuration>" + std::to_string(10 * kTimeScale) +
         "s</LeaseDuration></Discovery>";
}

}  // namespace sl::test
