#include "reader_acks.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>

#include <dds/ddsi/ddsi_guid.h>

#include "sl/daemon/log.h"

// Exported by libddsc (0.10.2, Debian 12) but declared only in its
// uninstalled headers dds__entity.h and dds__writer.h. The writer stays
// pinned (not locked) while waiting, so writes go on meanwhile.
extern "C" {
struct dds_entity;
struct dds_writer;
dds_return_t dds_entity_pin(dds_entity_t handle, struct dds_entity** entity);
void dds_entity_unpin(struct dds_entity* entity);
dds_return_t dds__ddsi_writer_wait_for_acks(struct dds_writer* writer, ddsi_guid_t* reader_guid,
                                            dds_time_t abstimeout);
}

namespace sl::daemon {

namespace {

constexpr dds_duration_t kWaitPerReader = DDS_MSECS(20);
constexpr auto kRefreshPeriod = std::chrono::milliseconds(100);

std::uint32_t loadBigEndian(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         std::uint32_t{p[3]};
}

std::string guidText(const unsigned char key[16]) {
  char text[40];
  std::snprintf(text, sizeof text, "%x:%x:%x:%x", loadBigEndian(key), loadBigEndian(key + 4),
                loadBigEndian(key + 8), loadBigEndian(key + 12));
  return text;
}

}  // namespace

ReaderAckMonitor::ReaderAckMonitor(dds_entity_t writer, std::int32_t history_depth)
    : writer_(writer), depth_(history_depth > 0 ? static_cast<std::uint64_t>(history_depth) : 0) {
  thread_ = std::thread([this] { run(); });
}

ReaderAckMonitor::~ReaderAckMonitor() {
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void ReaderAckMonitor::written() {
  const std::uint64_t n = ++written_;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    counted_[n % kLostWindow] = false;  // the slot held sample n - kLostWindow
    if (depth_ > 0 && n > depth_) {
      const std::uint64_t pushed_out = n - depth_;
      bool anyone = false;
      for (auto& [handle, r] : readers_) {
        // A reader is owed the samples written after it matched
        // (acked_through starts there) and acknowledges them or not.
        if (!r.state.reliable || std::max(r.acked_through, r.lost_through) >= pushed_out) continue;
        ++r.state.lost;
        r.lost_through = pushed_out;
        anyone = true;
        if (r.state.acknowledging) {
          r.state.acknowledging = false;
          logWarning("points reader " + r.state.guid + " stopped acknowledging: cloud " +
                     std::to_string(pushed_out) + " left the writer's history of " +
                     std::to_string(depth_) + " unacknowledged (lost for that reader)");
        }
      }
      if (anyone) countLost(pushed_out);
    }
  }
  wake_.notify_all();
}

std::vector<MatchedReaderState> ReaderAckMonitor::readers() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  std::vector<const Reader*> sorted;
  for (const auto& [handle, r] : readers_) sorted.push_back(&r);
  std::sort(sorted.begin(), sorted.end(),
            [](const Reader* a, const Reader* b) { return a->order < b->order; });
  std::vector<MatchedReaderState> out;
  for (const Reader* r : sorted) out.push_back(r->state);
  return out;
}

void ReaderAckMonitor::countLost(std::uint64_t n) {
  const std::uint64_t newest = written_.load();
  if (n + kLostWindow > newest) {
    if (counted_[n % kLostWindow]) return;
    counted_[n % kLostWindow] = true;
  }
  ++lost_total_;
}

void ReaderAckMonitor::welcomeBack(Reader& r, std::uint64_t written_now) {
  const std::uint64_t from = std::max(r.acked_through, r.lost_through);
  const std::uint64_t gap = written_now > from ? written_now - from : 0;
  if (r.state.reliable) {
    for (std::uint64_t n = from + 1; n <= written_now; ++n) countLost(n);
    r.state.lost += gap;
  }
  logWarning("points reader " + r.state.guid + " matched again after its lease expired: " +
             std::to_string(r.state.reliable ? gap : 0) +
             " clouds written while it was away are lost to it (" +
             std::to_string(r.state.lost) + " in all)");
  r.lost_through = written_now;
}

void ReaderAckMonitor::refreshMatched() {
  dds_instance_handle_t handles[64];
  const dds_return_t n = dds_get_matched_subscriptions(writer_, handles, 64);
  if (n < 0) return;
  const std::uint64_t written_now = written_.load();
  const std::lock_guard<std::mutex> lock(mutex_);
  for (auto& [handle, r] : readers_) r.seen = false;
  for (dds_return_t i = 0; i < std::min<dds_return_t>(n, 64); ++i) {
    auto it = readers_.find(handles[i]);
    if (it != readers_.end()) {
      it->second.seen = true;
      continue;
    }
    dds_builtintopic_endpoint_t* data = dds_get_matched_subscription_data(writer_, handles[i]);
    if (!data) continue;  // gone meanwhile
    Reader r;
    std::memcpy(r.key, data->key.v, 16);
    const std::string guid = guidText(r.key);
    const auto back = departed_.find(guid);
    const bool returning = back != departed_.end();
    if (returning) {
      r = back->second;  // keeps its place in readers() and its count
      departed_.erase(back);
      welcomeBack(r, written_now);
    }
    r.state.guid = guid;
    dds_reliability_kind_t kind = DDS_RELIABILITY_BEST_EFFORT;
    dds_duration_t blocking = 0;
    r.state.reliable = dds_qget_reliability(data->qos, &kind, &blocking) &&
                       kind == DDS_RELIABILITY_RELIABLE;
    dds_builtintopic_free_endpoint(data);
    r.acked_through = written_now;  // not owed what was written before it matched
    if (!returning) r.order = next_order_++;
    r.seen = true;
    readers_.emplace(handles[i], r);
  }
  for (auto it = readers_.begin(); it != readers_.end();) {
    if (it->second.seen) {
      ++it;
      continue;
    }
    Reader gone = it->second;
    it = readers_.erase(it);
    gone.departed = next_departure_++;
    departed_[gone.state.guid] = gone;
    if (departed_.size() > kDepartedKept) {
      auto oldest = std::min_element(departed_.begin(), departed_.end(), [](const auto& a, const auto& b) {
        return a.second.departed < b.second.departed;
      });
      departed_.erase(oldest);
    }
  }
}

bool ReaderAckMonitor::waitForAcks(const unsigned char key[16], dds_duration_t timeout) {
  ddsi_guid_t guid;  // host byte order, as Cyclone keeps GUIDs inside
  for (int i = 0; i < 3; ++i) guid.prefix.u[i] = loadBigEndian(key + 4 * i);
  guid.entityid.u = loadBigEndian(key + 12);
  dds_entity* entity = nullptr;
  if (dds_entity_pin(writer_, &entity) < 0) return true;  // writer deleted: nothing to wait for
  const dds_return_t rc = dds__ddsi_writer_wait_for_acks(reinterpret_cast<dds_writer*>(entity),
                                                         &guid, dds_time() + timeout);
  dds_entity_unpin(entity);
  return rc == DDS_RETCODE_OK;
}

void ReaderAckMonitor::run() {
  auto next_refresh = std::chrono::steady_clock::now();
  for (;;) {
    if (std::chrono::steady_clock::now() >= next_refresh) {
      refreshMatched();
      next_refresh = std::chrono::steady_clock::now() + kRefreshPeriod;
    }
    // The readers owing acknowledgements for what is written now.
    const std::uint64_t ref = written_.load();
    std::vector<std::pair<dds_instance_handle_t, Reader>> pending;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      if (stopping_) return;
      for (const auto& [handle, r] : readers_)
        if (r.state.reliable && r.acked_through < ref) pending.emplace_back(handle, r);
      if (pending.empty()) {
        wake_.wait_until(lock, next_refresh,
                         [&] { return stopping_ || written_.load() != ref; });
        continue;
      }
    }
    for (const auto& [handle, r] : pending) {
      if (!waitForAcks(r.key, kWaitPerReader)) continue;
      const std::lock_guard<std::mutex> lock(mutex_);
      auto it = readers_.find(handle);
      if (it == readers_.end()) continue;
      Reader& live = it->second;
      live.acked_through = std::max(live.acked_through, ref);
      if (!live.state.acknowledging) {
        live.state.acknowledging = true;
        logInfo("points reader " + live.state.guid + " acknowledges again (" +
                std::to_string(live.state.lost) + " clouds lost to it so far)");
      }
    }
  }
}

}  // namespace sl::daemon
