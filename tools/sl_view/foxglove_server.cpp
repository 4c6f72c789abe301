#include "foxglove_server.h"

#include <json/json.h>

#include <websocketpp/config/asio_no_tls.hpp>
#include <websocketpp/server.hpp>

#include <atomic>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>

namespace sl::view {

namespace {

using Endpoint = websocketpp::server<websocketpp::config::asio>;
using Hdl = websocketpp::connection_hdl;

constexpr const char* kSubprotocol = "foxglove.websocket.v1";

std::string toJson(const Json::Value& v) {
  Json::StreamWriterBuilder b;
  b["indentation"] = "";
  return Json::writeString(b, v);
}

// {"op": op, key: [item(x) for x in items]} as JSON text.
template <typename T, typename F>
std::string opWithList(const char* op, const char* key, const std::vector<T>& items, F item) {
  Json::Value v;
  v["op"] = op;
  v[key] = Json::Value(Json::arrayValue);
  for (const auto& x : items) v[key].append(item(x));
  return toJson(v);
}

void putU32(std::string& s, std::uint32_t v) {
  char b[4];
  std::memcpy(b, &v, 4);  // little-endian host (x86-64, aarch64)
  s.append(b, 4);
}
void putU64(std::string& s, std::uint64_t v) {
  char b[8];
  std::memcpy(b, &v, 8);
  s.append(b, 8);
}
std::uint32_t getU32(const std::string& s, std::size_t at) {
  std::uint32_t v;
  std::memcpy(&v, s.data() + at, 4);
  return v;
}

const char* contentType(const std::string& path) {
  const auto ends = [&](const char* ext) {
    const std::size_t n = std::strlen(ext);
    return path.size() >= n && path.compare(path.size() - n, n, ext) == 0;
  };
  if (ends(".html")) return "text/html; charset=utf-8";
  if (ends(".js") || ends(".mjs")) return "text/javascript; charset=utf-8";
  if (ends(".css")) return "text/css; charset=utf-8";
  if (ends(".json")) return "application/json";
  if (ends(".png")) return "image/png";
  return "application/octet-stream";
}

struct Queued {
  std::uint64_t sequence = 0;
  std::uint32_t subscription = 0;
  OutMessage message;
};

struct Client {
  Endpoint::connection_ptr connection;
  std::string remote;
  std::map<std::uint32_t, std::uint32_t> subscriptions;  // subscription id -> channel
  std::map<std::uint32_t, std::deque<Queued>> queues;    // per subscription id
  std::uint32_t last_served = 0;                         // subscription id
  std::uint64_t sent = 0, dropped = 0;
};

struct ServiceCall {
  Hdl hdl;
  std::uint32_t service = 0, call = 0;
  std::string encoding, payload;
};

}  // namespace

struct FoxgloveServer::Impl {
  ServerOptions options;
  std::vector<ChannelInfo> channels;
  std::vector<ServiceInfo> services;
  Endpoint endpoint;
  std::thread io_thread;
  int bound_port = 0;

  mutable std::mutex mu;  // clients, counters
  std::map<Hdl, Client, std::owner_less<Hdl>> clients;
  std::map<std::uint32_t, int> subscriber_count;  // channel -> subscriptions
  std::atomic<int> any_subscribed{0};
  std::uint64_t next_sequence = 1;
  std::uint64_t published = 0, total_sent = 0, total_dropped = 0;
  std::atomic<bool> pump_posted{false};

  // Service calls run on their own thread so a slow daemon never holds the
  // WebSocket thread.
  std::mutex call_mu;
  std::condition_variable call_cv;
  std::deque<ServiceCall> calls;
  bool stopping = false;
  std::thread call_thread;

  std::atomic<bool> stopped{false};

  void sendText(Hdl hdl, const std::string& text) {
    websocketpp::lib::error_code ec;
    endpoint.send(hdl, text, websocketpp::frame::opcode::text, ec);
  }

  void sendStatus(Hdl hdl, int level, const std::string& message) {
    Json::Value v;
    v["op"] = "status";
    v["level"] = level;
    v["message"] = message;
    sendText(hdl, toJson(v));
  }

  bool onValidate(Hdl hdl) {
    auto con = endpoint.get_con_from_hdl(hdl);
    for (const auto& p : con->get_requested_subprotocols()) {
      if (p == kSubprotocol) {
        con->select_subprotocol(kSubprotocol);
        return true;
      }
    }
    con->set_status(websocketpp::http::status_code::bad_request);
    con->set_body(std::string("sl_view speaks only the ") + kSubprotocol + " subprotocol\n");
    return false;
  }

  void onOpen(Hdl hdl) {
    auto con = endpoint.get_con_from_hdl(hdl);
    {
      std::lock_guard<std::mutex> lock(mu);
      Client& c = clients[hdl];
      c.connection = con;
      websocketpp::lib::error_code ec;
      c.remote = con->get_remote_endpoint();
    }
    Json::Value info;
    info["op"] = "serverInfo";
    info["name"] = options.name;
    info["capabilities"] = Json::Value(Json::arrayValue);
    if (!services.empty()) {
      info["capabilities"].append("services");
      info["supportedEncodings"].append("json");
    }
    info["sessionId"] = std::to_string(std::chrono::system_clock::now().time_since_epoch().count());
    sendText(hdl, toJson(info));
    sendText(hdl, opWithList("advertise", "channels", channels, [](const ChannelInfo& ch) {
      Json::Value c;
      c["id"] = ch.id;
      c["topic"] = ch.topic;
      c["encoding"] = ch.encoding;
      c["schemaName"] = ch.schema_name;
      c["schema"] = ch.schema;
      c["schemaEncoding"] = ch.schema_encoding;
      return c;
    }));
    if (!services.empty())
      sendText(hdl, opWithList("advertiseServices", "services", services, [](const ServiceInfo& svc) {
        Json::Value s;
        s["id"] = svc.id;
        s["name"] = svc.name;
        s["type"] = svc.type;
        s["requestSchema"] = "";
        s["responseSchema"] = "";
        return s;
      }));
  }

  void onClose(Hdl hdl) {
    std::lock_guard<std::mutex> lock(mu);
    auto it = clients.find(hdl);
    if (it == clients.end()) return;
    for (const auto& [sub, channel] : it->second.subscriptions) {
      (void)sub;
      --subscriber_count[channel];
      --any_subscribed;
    }
    clients.erase(it);
  }

  bool channelExists(std::uint32_t id) const {
    for (const auto& c : channels)
      if (c.id == id) return true;
    return false;
  }

  void onText(Hdl hdl, const std::string& text) {
    Json::Value msg;
    Json::CharReaderBuilder b;
    std::string errors;
    std::istringstream in(text);
    if (!Json::parseFromStream(b, in, &msg, &errors) || !msg.isObject() || !msg["op"].isString()) {
      sendStatus(hdl, 2, "malformed message (expected a JSON object with \"op\"): " + errors);
      return;
    }
    const std::string op = msg["op"].asString();
    if (op == "subscribe") {
      std::lock_guard<std::mutex> lock(mu);
      auto it = clients.find(hdl);
      if (it == clients.end()) return;
      for (const auto& s : msg["subscriptions"]) {
        const auto id = s["id"].asUInt();
        const auto channel = s["channelId"].asUInt();
        if (!channelExists(channel)) {
          sendStatus(hdl, 2, "subscribe: no channel " + std::to_string(channel));
          continue;
        }
        if (it->second.subscriptions.count(id)) {
          sendStatus(hdl, 2, "subscribe: subscription id " + std::to_string(id) + " is in use");
          continue;
        }
        it->second.subscriptions[id] = channel;
        ++subscriber_count[channel];
        ++any_subscribed;
      }
    } else if (op == "unsubscribe") {
      std::lock_guard<std::mutex> lock(mu);
      auto it = clients.find(hdl);
      if (it == clients.end()) return;
      for (const auto& s : msg["subscriptionIds"]) {
        const auto id = s.asUInt();
        auto sub = it->second.subscriptions.find(id);
        if (sub == it->second.subscriptions.end()) continue;
        --subscriber_count[sub->second];
        --any_subscribed;
        it->second.subscriptions.erase(sub);
        it->second.queues.erase(id);
      }
    } else {
      sendStatus(hdl, 1, "unsupported op '" + op + "'");
    }
  }

  void onBinary(Hdl hdl, const std::string& payload) {
    if (payload.empty()) return;
    if (payload[0] != 0x02 || services.empty()) {
      sendStatus(hdl, 1, "unsupported binary opcode " + std::to_string(payload[0]));
      return;
    }
    if (payload.size() < 13) {
      sendStatus(hdl, 2, "service call request shorter than its 13-byte header");
      return;
    }
    ServiceCall call;
    call.hdl = hdl;
    call.service = getU32(payload, 1);
    call.call = getU32(payload, 5);
    const std::uint32_t enc_len = getU32(payload, 9);
    if (payload.size() < 13 + std::size_t{enc_len}) {
      sendStatus(hdl, 2, "service call request: encoding length beyond the message");
      return;
    }
    call.encoding = payload.substr(13, enc_len);
    call.payload = payload.substr(13 + enc_len);
    std::lock_guard<std::mutex> lock(call_mu);
    calls.push_back(std::move(call));
    call_cv.notify_one();
  }

  void serviceLoop() {
    for (;;) {
      ServiceCall call;
      {
        std::unique_lock<std::mutex> lock(call_mu);
        call_cv.wait(lock, [&] { return stopping || !calls.empty(); });
        if (stopping) return;
        call = std::move(calls.front());
        calls.pop_front();
      }
      const ServiceInfo* svc = nullptr;
      for (const auto& s : services)
        if (s.id == call.service) svc = &s;
      std::string failure, response;
      if (svc == nullptr) {
        failure = "no service " + std::to_string(call.service);
      } else if (call.encoding != "json") {
        failure = "service " + svc->name + ": encoding '" + call.encoding + "' (only json)";
      } else {
        try {
          response = svc->handler(call.payload);
        } catch (const std::exception& e) {
          failure = svc->name + ": " + e.what();
        }
      }
      std::string frame;
      if (failure.empty()) {
        frame.push_back(0x03);
        putU32(frame, call.service);
        putU32(frame, call.call);
        putU32(frame, 4);
        frame += "json";
        frame += response;
      }
      boost::asio::post(endpoint.get_io_service(), [this, call, failure, frame] {
        if (!failure.empty()) {
          Json::Value v;
          v["op"] = "serviceCallFailure";
          v["serviceId"] = call.service;
          v["callId"] = call.call;
          v["message"] = failure;
          sendText(call.hdl, toJson(v));
        } else {
          websocketpp::lib::error_code ec;
          endpoint.send(call.hdl, frame, websocketpp::frame::opcode::binary, ec);
        }
      });
    }
  }

  void onHttp(Hdl hdl) {
    auto con = endpoint.get_con_from_hdl(hdl);
    std::string path = con->get_resource();
    if (const auto q = path.find('?'); q != std::string::npos) path.resize(q);
    if (path == "/stats") {
      const ServerStats s = statsLocked();
      Json::Value v;
      v["published"] = Json::UInt64(s.published);
      v["sent"] = Json::UInt64(s.sent);
      v["dropped"] = Json::UInt64(s.dropped);
      v["clients"] = Json::Value(Json::arrayValue);
      for (const auto& c : s.clients) {
        Json::Value j;
        j["remote"] = c.remote;
        j["sent"] = Json::UInt64(c.sent);
        j["dropped"] = Json::UInt64(c.dropped);
        j["queued"] = Json::UInt64(c.queued);
        j["inFlightBytes"] = Json::UInt64(c.in_flight_bytes);
        j["subscriptions"] = Json::UInt64(c.subscriptions);
        v["clients"].append(j);
      }
      if (options.dds_stats) {
        Json::CharReaderBuilder builder;
        std::string errors;
        std::istringstream in(options.dds_stats());
        Json::Value dds;
        if (Json::parseFromStream(builder, in, &dds, &errors)) v["dds"] = dds;
      }
      con->set_status(websocketpp::http::status_code::ok);
      con->append_header("Content-Type", "application/json");
      con->append_header("Cache-Control", "no-store");
      con->set_body(toJson(v));
      return;
    }
    if (path.find("..") != std::string::npos || path.find('\\') != std::string::npos) {
      con->set_status(websocketpp::http::status_code::bad_request);
      con->set_body("bad path\n");
      return;
    }
    if (!path.empty() && path.back() == '/') path += "index.html";
    const std::pair<std::string, std::string>* best = nullptr;
    for (const auto& d : options.static_dirs)
      if (path.rfind(d.first, 0) == 0 && (best == nullptr || d.first.size() > best->first.size()))
        best = &d;
    if (best != nullptr) {
      const std::string file = best->second + "/" + path.substr(best->first.size());
      std::ifstream in(file, std::ios::binary);
      if (in) {
        std::ostringstream body;
        body << in.rdbuf();
        con->set_status(websocketpp::http::status_code::ok);
        con->append_header("Content-Type", contentType(file));
        con->append_header("Cache-Control", "no-cache");
        con->set_body(body.str());
        return;
      }
    }
    con->set_status(websocketpp::http::status_code::not_found);
    con->append_header("Content-Type", "text/plain");
    con->set_body("not found: " + path +
                  (path.rfind("/three/", 0) == 0
                       ? " (three.js comes from npm: run `npm ci` in tools/sl_view)\n"
                       : "\n"));
  }

  ServerStats statsLocked() const {
    std::lock_guard<std::mutex> lock(mu);
    ServerStats s;
    s.published = published;
    s.sent = total_sent;
    s.dropped = total_dropped;
    for (const auto& [hdl, c] : clients) {
      (void)hdl;
      ClientStats cs;
      cs.remote = c.remote;
      cs.sent = c.sent;
      cs.dropped = c.dropped;
      cs.subscriptions = c.subscriptions.size();
      for (const auto& [id, q] : c.queues) {
        (void)id;
        cs.queued += q.size();
      }
      cs.in_flight_bytes = c.connection ? c.connection->get_buffered_amount() : 0;
      s.clients.push_back(cs);
    }
    return s;
  }

  void publish(OutMessage message) {
    {
      std::lock_guard<std::mutex> lock(mu);
      const auto count = subscriber_count.find(message.channel);
      if (count == subscriber_count.end() || count->second <= 0) return;
      ++published;
      const std::uint64_t seq = next_sequence++;
      for (auto& [hdl, c] : clients) {
        (void)hdl;
        for (const auto& [sub, channel] : c.subscriptions) {
          if (channel != message.channel) continue;
          auto& q = c.queues[sub];
          q.push_back(Queued{seq, sub, message});
          while (q.size() > options.queue_depth) {
            q.pop_front();  // the oldest goes: a viewer wants the latest
            ++c.dropped;
            ++total_dropped;
          }
        }
      }
    }
    if (!pump_posted.exchange(true))
      boost::asio::post(endpoint.get_io_service(), [this] { pump(); });
  }

  // On the WebSocket thread: hands each client its oldest queued messages
  // while its socket has room.
  void pump() {
    pump_posted = false;
    for (;;) {
      Endpoint::connection_ptr con;
      Queued next;
      {
        std::lock_guard<std::mutex> lock(mu);
        for (auto& [hdl, c] : clients) {
          (void)hdl;
          if (!c.connection || c.connection->get_buffered_amount() >= options.max_in_flight_bytes)
            continue;
          // Subscriptions take turns (the next non-empty queue after the
          // one served last): a viewer slower than the sensor still gets
          // the latest of every topic, not only of those published first
          // in a scan (a 25 MB cloud ahead of its camera_info every time).
          std::deque<Queued>* turn = nullptr;
          auto it = c.queues.upper_bound(c.last_served);
          for (std::size_t k = 0; k < c.queues.size() && turn == nullptr; ++k, ++it) {
            if (it == c.queues.end()) it = c.queues.begin();
            if (!it->second.empty()) {
              turn = &it->second;
              c.last_served = it->first;
            }
          }
          if (turn == nullptr) continue;
          next = std::move(turn->front());
          turn->pop_front();
          ++c.sent;
          ++total_sent;
          con = c.connection;
          break;
        }
      }
      if (!con) return;
      auto msg = con->get_message(websocketpp::frame::opcode::binary, 13 + next.message.bytes.size());
      std::string& payload = msg->get_raw_payload();
      payload.reserve(13 + next.message.bytes.size());
      payload.push_back(0x01);
      putU32(payload, next.subscription);
      putU64(payload, next.message.receive_ns);
      payload.append(next.message.bytes.data(), next.message.bytes.size());
      con->send(msg);
    }
  }

  void tick() {
    pump();
    if (!stopped) endpoint.set_timer(5, [this](const websocketpp::lib::error_code&) { tick(); });
  }
};

FoxgloveServer::FoxgloveServer(const ServerOptions& options, std::vector<ChannelInfo> channels,
                               std::vector<ServiceInfo> services)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.options = options;
  m.channels = std::move(channels);
  m.services = std::move(services);
  m.endpoint.clear_access_channels(websocketpp::log::alevel::all);
  // A viewer that goes away mid-message is normal: no websocketpp logging.
  m.endpoint.clear_error_channels(websocketpp::log::elevel::all);
  m.endpoint.init_asio();
  m.endpoint.set_reuse_addr(true);
  m.endpoint.set_validate_handler([&m](Hdl h) { return m.onValidate(h); });
  m.endpoint.set_open_handler([&m](Hdl h) { m.onOpen(h); });
  m.endpoint.set_close_handler([&m](Hdl h) { m.onClose(h); });
  m.endpoint.set_fail_handler([&m](Hdl h) { m.onClose(h); });
  m.endpoint.set_http_handler([&m](Hdl h) { m.onHttp(h); });
  m.endpoint.set_message_handler([&m](Hdl h, Endpoint::message_ptr msg) {
    if (msg->get_opcode() == websocketpp::frame::opcode::text)
      m.onText(h, msg->get_payload());
    else
      m.onBinary(h, msg->get_payload());
  });
  websocketpp::lib::error_code ec;
  boost::system::error_code addr_ec;
  const auto address = boost::asio::ip::make_address(options.host, addr_ec);
  if (addr_ec)
    throw std::runtime_error("'" + options.host + "' is not an IP address to listen on");
  const boost::asio::ip::tcp::endpoint where(address, static_cast<unsigned short>(options.port));
  m.endpoint.listen(where, ec);
  if (ec) {
    // websocketpp says only "Underlying Transport Error": ask the system why.
    std::string why = ec.message();
    boost::asio::io_context io;
    boost::asio::ip::tcp::acceptor probe(io);
    boost::system::error_code probe_ec;
    probe.open(where.protocol(), probe_ec);
    if (!probe_ec) probe.bind(where, probe_ec);
    if (probe_ec) why = probe_ec.message();
    const bool in_use = probe_ec == boost::asio::error::address_in_use;
    throw std::runtime_error("cannot listen on " + options.host + ":" + std::to_string(options.port) +
                             ": " + why + (in_use ? " (another sl_view? --port N picks another)" : ""));
  }
  m.endpoint.start_accept(ec);
  if (ec) throw std::runtime_error("accept: " + ec.message());
  websocketpp::lib::asio::error_code local_ec;
  m.bound_port = m.endpoint.get_local_endpoint(local_ec).port();
  m.endpoint.set_timer(5, [&m](const websocketpp::lib::error_code&) { m.tick(); });
  m.io_thread = std::thread([&m] { m.endpoint.run(); });
  m.call_thread = std::thread([&m] { m.serviceLoop(); });
}

FoxgloveServer::~FoxgloveServer() { stop(); }

int FoxgloveServer::port() const { return impl_->bound_port; }

bool FoxgloveServer::subscribed(std::uint32_t channel) const {
  if (impl_->any_subscribed.load() <= 0) return false;
  std::lock_guard<std::mutex> lock(impl_->mu);
  const auto it = impl_->subscriber_count.find(channel);
  return it != impl_->subscriber_count.end() && it->second > 0;
}

void FoxgloveServer::publish(OutMessage message) { impl_->publish(std::move(message)); }

ServerStats FoxgloveServer::stats() const { return impl_->statsLocked(); }

void FoxgloveServer::stop() {
  Impl& m = *impl_;
  if (m.stopped.exchange(true)) return;
  {
    std::lock_guard<std::mutex> lock(m.call_mu);
    m.stopping = true;
    m.call_cv.notify_all();
  }
  if (m.call_thread.joinable()) m.call_thread.join();
  m.endpoint.get_io_service().post([&m] {
    websocketpp::lib::error_code ec;
    m.endpoint.stop_listening(ec);
    std::vector<Endpoint::connection_ptr> open;
    {
      std::lock_guard<std::mutex> lock(m.mu);
      for (auto& [h, c] : m.clients) {
        (void)h;
        if (c.connection) open.push_back(c.connection);
      }
    }
    for (auto& c : open) c->close(websocketpp::close::status::going_away, "sl_view stops", ec);
    m.endpoint.stop();
  });
  if (m.io_thread.joinable()) m.io_thread.join();
}

}  // namespace sl::view
