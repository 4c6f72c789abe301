#include "sl/pipeline/decoder.h"

#include "sl/pipeline/pattern_spec.h"

namespace sl::pipeline {

Decoder::Decoder(const PatternSpec& spec, const DecoderOptions& options)
    : codec_(makeCodec(spec, options)) {}

PhaseShift33Decoder::PhaseShift33Decoder(PhaseShift33Pattern pattern, DecoderOptions options)
    : pattern_(std::move(pattern)), decoder_((pattern_.validate(), toSpec(pattern_)), options) {}

}  // namespace sl::pipeline
