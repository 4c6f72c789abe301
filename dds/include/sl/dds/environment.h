// The daemon's start-up check of its DDS environment: what the Cyclone DDS
// configuration (CYCLONEDDS_URI) asks of the kernel and of the iceoryx
// shared-memory service, against what they can give. Cyclone itself
// silently takes less (a socket buffer capped at net.core.rmem_max) or waits
// 60 s and aborts (no RouDi); the daemon says so in one line instead.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace sl::dds {

// What the configuration asks for (the largest value over every domain
// section and every file of the URI; nullopt where it sets nothing).
struct DdsRequirements {
  std::optional<std::int64_t> receive_buffer_bytes;  // Internal/SocketReceiveBufferSize max
  std::optional<std::int64_t> send_buffer_bytes;     // Internal/SocketSendBufferSize max
  bool shared_memory = false;                         // SharedMemory/Enable true
  // What a second DDS stack in the daemon (fastdds_services.h) must bind to
  // and talk to, to stay where Cyclone is: the IPv4 addresses of
  // General/Interfaces/NetworkInterface address= (and the older
  // General/NetworkInterfaceAddress), of Discovery/Peers/Peer address=, and
  // General/AllowMulticast.
  std::vector<std::string> interface_addresses;
  std::vector<std::string> peer_addresses;
  bool allow_multicast = true;                        // AllowMulticast false: false
  bool security = false;                              // a Security / DDSSecurity section
  std::vector<std::string> sources;                   // files read ("inline XML" for text)
};

// Reads the XML of a CYCLONEDDS_URI value: comma-separated file:// URIs,
// plain paths or inline XML (as Cyclone accepts). Throws std::runtime_error
// naming the file it cannot read. Sizes take Cyclone's units (B, KB, KiB,
// MB, MiB, GB, GiB; "default" = not set).
DdsRequirements readDdsRequirements(const std::string& cyclonedds_uri);

struct DdsHost {
  std::int64_t rmem_max = 0;  // net.core.rmem_max, bytes
  std::int64_t wmem_max = 0;  // net.core.wmem_max, bytes
  bool roudi_running = false; // the iceoryx RouDi socket exists
};

// The host as it is: /proc/sys/net/core/{rmem,wmem}_max and /tmp/roudi.
DdsHost currentDdsHost();

// One line per shortfall, each naming the setting to change (the shipped
// sysctl drop-in, the RouDi unit); empty when the host gives everything.
std::vector<std::string> ddsEnvironmentProblems(const DdsRequirements& wanted, const DdsHost& host);

}  // namespace sl::dds
