// Pattern files from other rigs' conventions: fringe pitches in projector
// px, the unwrapping margin checked at load time, frames to skip, Gray +
// phase shift thresholded against the fringe mean, errors that blame the
// right key.
#include <cmath>
#include <string>
#include <vector>

#include <catch2/catch.hpp>

#include "sl/daemon/config.h"
#include "sl/files/pattern_config.h"
#include "sl/pipeline/codec.h"

using namespace sl;
using pipeline::PatternFamily;
using pipeline::PatternSpec;

namespace {

std::string loadError(const std::string& text) {
  try {
    files::parsePatternText(text, "p.yaml");
  } catch (const files::ConfigError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("a fringe pitch in projector px is any positive number", "[codecs][yaml][conventions]") {
  const PatternSpec p = files::parsePatternText(
      "family: phase_shift\ndirection: horizontal\nsteps: 3\npitches_px: [60, 1824]\n", "p.yaml");
  REQUIRE(p.frequencies.size() == 2);
  CHECK(p.frequencies[0] == Approx(1824.0 / 60));
  CHECK(p.frequencies[1] == Approx(1.0));
  CHECK(p.finestPeriod(1824) == Approx(60.0));
  // Rows: the pitch is along the projector's 1140 rows.
  const PatternSpec v = files::parsePatternText(
      "family: phase_shift\ndirection: vertical\nsteps: 4\npitches_px: [57, 1140]\n", "p.yaml");
  CHECK(v.frequencies[0] == Approx(20.0));
  // The paper's 3+3 with a pitch, or a non-integer number of periods.
  const PatternSpec p33 = files::parsePatternText(
      "family: phase_shift_3+3\ndirection: horizontal\npitch_px: 60\n", "p.yaml");
  CHECK(p33.frequencies[0] == Approx(30.4));
  const PatternSpec f33 = files::parsePatternText(
      "family: phase_shift_3+3\ndirection: horizontal\nfringes: 30.4\n", "p.yaml");
  CHECK(f33.frequencies[0] == Approx(30.4));
  CHECK_NOTHROW(pipeline::makeCodec(p, {}));
  // Both directions of a non-square projector cannot share a pitch in px.
  CHECK(loadError("family: phase_shift\ndirection: both\npitches_px: [60, 1824]\n")
            .find("key 'pitches_px'") != std::string::npos);
  CHECK(loadError("family: phase_shift\ndirection: horizontal\npitches_px: [60, 1824]\n"
                  "frequencies: [16, 1]\n")
            .find("give exactly one") != std::string::npos);
  CHECK(loadError("family: phase_shift\ndirection: horizontal\npitches_px: [-60, 1824]\n")
            .find("key 'pitches_px'") != std::string::npos);
}

TEST_CASE("frequencies that cannot unwrap are refused at load time with the numbers",
          "[codecs][yaml][conventions]") {
  // 6 px fringes straight from a unit cue: the step (ratio 304) needs about
  // 150 DN of fringe modulation for 5-sigma fringe orders.
  const std::string e =
      loadError("family: phase_shift\ndirection: horizontal\nsteps: 3\npitches_px: [6, 1824]\n");
  CAPTURE(e);
  CHECK(e.find("key 'pitches_px'") != std::string::npos);
  CHECK(e.find("cannot be unwrapped") != std::string::npos);
  CHECK(e.find("304") != std::string::npos);
  const std::string f =
      loadError("family: phase_shift_3+3\ndirection: horizontal\nfringes: 300\n");
  CHECK(f.find("key 'fringes'") != std::string::npos);
  CHECK(f.find("cannot be unwrapped") != std::string::npos);
  // With an intermediate frequency the same fine fringes are fine.
  CHECK_NOTHROW(files::parsePatternText(
      "family: phase_shift\ndirection: horizontal\nsteps: 3\npitches_px: [6, 114, 1824]\n",
      "p.yaml"));
  // The limit is the formula's: PatternSpec itself refuses too.
  PatternSpec s;
  s.frequencies = {300, 1};
  CHECK_THROWS_AS(s.validate(), pipeline::PatternSpecError);
  s.frequencies = {300, 16, 1};
  CHECK_NOTHROW(s.validate());
}

TEST_CASE("frames that are not part of the code are skipped", "[codecs][yaml][conventions]") {
  // SLStudio-style Gray code + phase shift with a white and a black frame
  // after the Gray bits, thresholded against the fringe mean.
  const PatternSpec p = files::parsePatternText(
      "family: gray_phase_shift\ndirection: horizontal\nbits: 5\nsteps: 3\n"
      "reference_frames: false\ninverse: false\ncomplementary: true\nskip_frames: [6, 7]\n",
      "p.yaml");
  CHECK(p.codeFrameCount() == 6 + 3);
  CHECK(p.frameCount() == 11);
  REQUIRE(p.frame_order.size() == 11);
  CHECK(p.frame_order[5] == 5);
  CHECK(p.frame_order[6] == pipeline::kSkippedFrame);
  CHECK(p.frame_order[7] == pipeline::kSkippedFrame);
  CHECK(p.frame_order[8] == 6);
  const auto codec = pipeline::makeCodec(p, {});
  CHECK(codec->frameCount() == 11);
  CHECK(codec->generate().size() == 11);
  // The same with frame_order, which need not be a permutation now.
  const PatternSpec q = files::parsePatternText(
      "family: phase_shift\ndirection: horizontal\nfrequencies: [16, 1]\n"
      "frame_order: [-1, 3, 4, 5, -1, 0, 1, 2]\n",
      "p.yaml");
  CHECK(q.frameCount() == 8);
  CHECK(loadError("family: phase_shift\ndirection: horizontal\nfrequencies: [16, 1]\n"
                  "frame_order: [-1, 3, 4, 5, 0, 1]\n")
            .find("misses canonical frame 2") != std::string::npos);
  CHECK(loadError("family: phase_shift\ndirection: horizontal\nfrequencies: [16, 1]\n"
                  "skip_frames: [9]\n")
            .find("key 'skip_frames'") != std::string::npos);
  CHECK(loadError("family: phase_shift\ndirection: horizontal\nfrequencies: [16, 1]\n"
                  "skip_frames: [1]\nframe_order: [0, 1, 2, 3, 4, 5]\n")
            .find("give one of") != std::string::npos);
}

TEST_CASE("Gray + phase shift without references or inverses loads; errors blame the right key",
          "[codecs][yaml][conventions]") {
  // Once refused with a message about `bits`.
  const PatternSpec p = files::parsePatternText(
      "family: gray_phase_shift\ndirection: horizontal\nbits: 6\nsteps: 4\ncomplementary: true\n"
      "reference_frames: false\ninverse: false\n",
      "p.yaml");
  CHECK(p.frameCount() == 7 + 4);
  // Plain Gray code still needs a threshold, and says which key.
  const std::string e = loadError(
      "family: gray_code\ndirection: horizontal\nbits: 6\nreference_frames: false\ninverse: false\n");
  CHECK(e.find("key 'reference_frames'") != std::string::npos);
  CHECK(loadError("family: gray_phase_shift\ndirection: horizontal\nbits: 6\nsteps: 2\n")
            .find("key 'steps'") != std::string::npos);
  CHECK(loadError("family: gray_phase_shift\ndirection: horizontal\nbits: 6\nshift_sign: 1\n"
                  "amplitude: 0.6\n")
            .find("key 'amplitude'") != std::string::npos);
}

TEST_CASE("micro and modulated phase shifting in pattern files", "[codecs][yaml][conventions]") {
  const PatternSpec micro = files::parsePatternText(
      "family: micro_phase_shift\ndirection: horizontal\npitches_px: [16, 16.5, 17, 17.5, 18, 18.5]\n",
      "p.yaml");
  CHECK(micro.family == PatternFamily::kMicroPhaseShift);
  CHECK(micro.frameCount() == 8);
  CHECK(micro.microSeparation() > 0.01);
  // The derived threshold follows from the separation (5 sigma on the
  // closest wrong candidate).
  CHECK(pipeline::derivedMinModulation(micro, 0.3f) ==
        Approx(2 * 5 * 0.54 / std::sqrt(micro.microSeparation())).epsilon(1e-3));
  // Equally spaced pitches of 16..20 px repeat their cosines: refused with the number.
  const std::string e = loadError(
      "family: micro_phase_shift\ndirection: horizontal\npitches_px: [16, 17, 18, 19, 20]\n");
  CAPTURE(e);
  CHECK(e.find("key 'pitches_px'") != std::string::npos);
  CHECK(e.find("do not tell the periods") != std::string::npos);
  CHECK(loadError("family: micro_phase_shift\ndirection: horizontal\nfrequencies: [100]\n")
            .find("2..17 frequencies") != std::string::npos);
  const PatternSpec modulated = files::parsePatternText(
      "family: modulated_phase_shift\ndirection: vertical\nsteps: 4\nfrequencies: [16, 1]\n"
      "carrier_pitch_px: 10\n",
      "p.yaml");
  CHECK(modulated.frameCount() == 3 * 4 * 2);
  CHECK(modulated.carrier_pitch_px == 10);
  CHECK(loadError("family: modulated_phase_shift\ndirection: vertical\nfrequencies: [16, 1]\n"
                  "carrier_pitch_px: 2\n")
            .find("key 'carrier_pitch_px'") != std::string::npos);
  // The carrier runs along the other axis: a vertical pattern's frames vary
  // along both axes.
  const auto images = pipeline::makeCodec(modulated, {})->generate();
  CHECK(images[0].at<std::uint8_t>(100, 0) > images[0].at<std::uint8_t>(100, 5) + 10);
  CHECK(images[0].at<std::uint8_t>(100, 0) != images[0].at<std::uint8_t>(300, 0));
}
