// Factories of the codec families and their shared row-kernel base (private
// to the pipeline).
#pragma once

#include <cstdint>
#include <memory>

#include "sl/pipeline/codec.h"

namespace sl::pipeline::detail {

// Base of a codec whose row kernel is one member template over the pixel
// type, `template <typename Pixel> void row(const RowContext&, const Pixel*
// const* frames, int width, const RowOutput&) const` in Derived (which
// befriends this class): both pixel depths go to it, bound at compile time.
// A codec with a faster path for one depth overrides that decodeRow itself.
template <typename Derived>
class RowTemplateCodec : public Codec {
 protected:
  RowTemplateCodec(const PatternSpec& spec, const DecoderOptions& options) : Codec(spec, options) {}
  void decodeRow8(const RowContext& c, const std::uint8_t* const* frames, int width,
                  const RowOutput& out) const override {
    static_cast<const Derived&>(*this).row(c, frames, width, out);
  }
  void decodeRow16(const RowContext& c, const std::uint16_t* const* frames, int width,
                   const RowOutput& out) const override {
    static_cast<const Derived&>(*this).row(c, frames, width, out);
  }
};

// kPhaseShift and kTwoPlusOne.
std::unique_ptr<Codec> makePhaseShiftCodec(const PatternSpec& spec, const DecoderOptions& options);
// kGrayCode and kGrayPhaseShift.
std::unique_ptr<Codec> makeGrayCodec(const PatternSpec& spec, const DecoderOptions& options);
std::unique_ptr<Codec> makeMicroPhaseShiftCodec(const PatternSpec& spec,
                                                const DecoderOptions& options);
std::unique_ptr<Codec> makeModulatedPhaseShiftCodec(const PatternSpec& spec,
                                                    const DecoderOptions& options);

}  // namespace sl::pipeline::detail
