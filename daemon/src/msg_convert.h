// The daemon's name for the DDS message types and conversions: sl::dds::msg
// (idlc type names, stamps, string sequences) and the reply codes
// (sl::client), seen as sl::daemon::msg by the bridge, the request dispatch
// and the message builders (private to daemon/).
#pragma once

#include "sl/client/reply_codes.h"
#include "sl/dds/msg_convert.h"

namespace sl::daemon::msg {

using namespace ::sl::dds::msg;
using ::sl::client::fromReplyCode;
using ::sl::client::kReplyCodes;
using ::sl::client::toReplyCode;

}  // namespace sl::daemon::msg
