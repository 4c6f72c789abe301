// A Foxglove WebSocket server (subprotocol foxglove.websocket.v1) that
// forwards serialized messages to subscribed clients, answers service calls
// (JSON) and serves static files over plain HTTP on the same port.
//
// Back-pressure: every subscription of every client has a queue of at most
// `queue_depth` messages; publishing into a full queue drops its oldest
// message and counts it; a client's subscriptions take turns. Its next message is handed to the socket
// only when less than `max_in_flight_bytes` of the previous ones are still
// unsent, so a stalled viewer holds at most one message plus its queues and
// publish() never blocks (the DDS side never waits for a viewer).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace sl::view {

struct ServerOptions {
  std::string host = "127.0.0.1";  // listen address; "0.0.0.0" for every interface
  int port = 8765;                 // 0: any free port (see FoxgloveServer::port())
  std::size_t queue_depth = 2;     // per subscription
  std::size_t max_in_flight_bytes = std::size_t{1} << 20;
  // Static files: URL path prefix -> directory, e.g. {"/", web_dir},
  // {"/three/", node_modules/three}. Longest prefix wins.
  std::vector<std::pair<std::string, std::string>> static_dirs;
  std::string name = "sl_view";
  // Extra counters for GET /stats, as the text of a JSON value put under
  // "dds" (called on the server thread; must be thread-safe). Optional.
  std::function<std::string()> dds_stats;
};

struct ChannelInfo {
  std::uint32_t id = 0;
  std::string topic;            // "/sl/points"
  std::string encoding = "cdr";
  std::string schema_name;      // "sensor_msgs/msg/PointCloud2"
  std::string schema;           // ros2msg text
  std::string schema_encoding = "ros2msg";
};

// A message to forward: bytes that stay valid while `owner` lives.
struct OutMessage {
  std::uint32_t channel = 0;
  std::uint64_t receive_ns = 0;
  std::string_view bytes;
  std::shared_ptr<const void> owner;
};

// A service: JSON request in, JSON response out (or an exception whose
// what() goes back as serviceCallFailure). Called on a worker thread.
struct ServiceInfo {
  std::uint32_t id = 0;
  std::string name;  // "/sl/command"
  std::string type;  // "sl_msgs/srv/Command"
  std::function<std::string(const std::string& request)> handler;
};

struct ClientStats {
  std::string remote;
  std::uint64_t sent = 0, dropped = 0;
  std::size_t queued = 0, in_flight_bytes = 0, subscriptions = 0;
};

struct ServerStats {
  std::vector<ClientStats> clients;
  std::uint64_t published = 0;  // messages handed to publish() with a subscriber
  std::uint64_t sent = 0, dropped = 0;  // over all clients, including gone ones
};

class FoxgloveServer {
 public:
  // Binds and starts serving on its own thread; throws std::runtime_error
  // naming the address if it cannot listen.
  FoxgloveServer(const ServerOptions& options, std::vector<ChannelInfo> channels,
                 std::vector<ServiceInfo> services);
  ~FoxgloveServer();  // stops

  int port() const;
  // True if any client subscribes to the channel (cheap, any thread).
  bool subscribed(std::uint32_t channel) const;
  // Queues the message for every subscription of its channel; never blocks.
  void publish(OutMessage message);
  ServerStats stats() const;
  void stop();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sl::view
