// Factories of the codec families (private to the pipeline).
#pragma once

#include <memory>

#include "sl/pipeline/codec.h"

namespace sl::pipeline::detail {

// kPhaseShift and kTwoPlusOne.
std::unique_ptr<Codec> makePhaseShiftCodec(const PatternSpec& spec, const DecoderOptions& options);
// kGrayCode and kGrayPhaseShift.
std::unique_ptr<Codec> makeGrayCodec(const PatternSpec& spec, const DecoderOptions& options);
std::unique_ptr<Codec> makeMicroPhaseShiftCodec(const PatternSpec& spec,
                                                const DecoderOptions& options);
std::unique_ptr<Codec> makeModulatedPhaseShiftCodec(const PatternSpec& spec,
                                                    const DecoderOptions& options);

}  // namespace sl::pipeline::detail
