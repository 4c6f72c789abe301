#include "sl/dds/dds.h"

#include <malloc.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <climits>
#include <cstdlib>
#include <cstring>
#include <chrono>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace sl::dds {

Error::Error(const std::string& call, dds_return_t code)
    : std::runtime_error(call + ": " + dds_strretcode(code) + " (" + std::to_string(code) + ")"),
      code_(code) {}

dds_return_t check(dds_return_t rc, const std::string& call) {
  if (rc < 0) throw Error(call, rc);
  return rc;
}

bool retainLargeSampleMemory() {
  if (const char* keep = std::getenv("SL_DEFAULT_MALLOC"); keep && std::strcmp(keep, "1") == 0)
    return true;  // glibc's defaults, for comparisons (bench-delivery)
  bool ok = mallopt(M_MMAP_THRESHOLD, 32 << 20) == 1;
  ok = mallopt(M_TRIM_THRESHOLD, INT_MAX) == 1 && ok;
  ok = mallopt(M_TOP_PAD, 64 << 20) == 1 && ok;
  return ok;
}

void prefaultHeap(std::size_t block_bytes, std::size_t count) {
  constexpr std::size_t kLargestHeapBlock = std::size_t{32} << 20;  // the mmap threshold
  if (block_bytes == 0 || count == 0 || block_bytes >= kLargestHeapBlock) return;
  const std::size_t page = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
  std::vector<unsigned char*> blocks;
  blocks.reserve(count);
  for (std::size_t i = 0; i < count; ++i) {
    auto* block = static_cast<unsigned char*>(std::malloc(block_bytes));
    if (!block) break;  // what was touched still helps
    for (std::size_t offset = 0; offset < block_bytes; offset += page)
      static_cast<volatile unsigned char*>(block)[offset] = 0;
    blocks.push_back(block);
  }
  for (auto it = blocks.rbegin(); it != blocks.rend(); ++it) std::free(*it);
}

std::size_t populateSharedMemoryMappings() {
  const auto page = static_cast<std::uintptr_t>(sysconf(_SC_PAGESIZE));
  std::ifstream maps("/proc/self/maps");
  std::size_t populated = 0;
  for (std::string line; std::getline(maps, line);) {
    // start-end perms offset dev inode path
    std::istringstream fields(line);
    std::string range, perms, offset, dev, inode, path;
    fields >> range >> perms >> offset >> dev >> inode >> path;
    if (path.rfind("/dev/shm/", 0) != 0 || perms.size() < 2) continue;
    const std::size_t dash = range.find('-');
    if (dash == std::string::npos) continue;
    const auto start = static_cast<std::uintptr_t>(std::stoull(range.substr(0, dash), nullptr, 16));
    const auto end = static_cast<std::uintptr_t>(std::stoull(range.substr(dash + 1), nullptr, 16));
    const int advice = perms[1] == 'w' ? MADV_POPULATE_WRITE : MADV_POPULATE_READ;
    if (madvise(reinterpret_cast<void*>(start), end - start, advice) != 0 || perms[0] != 'r') continue;
    // The read pass (see dds.h): one byte per page, through a volatile so
    // that it is not optimised away.
    const auto* bytes = reinterpret_cast<const volatile unsigned char*>(start);
    unsigned char sink = 0;
    for (std::uintptr_t offset = 0; offset < end - start; offset += page) sink ^= bytes[offset];
    static_cast<void>(sink);
    populated += end - start;
  }
  return populated;
}

// --- Qos ---

Qos::Qos() : qos_(dds_create_qos()) {}

Qos::Qos(const Qos& other) : qos_(dds_create_qos()) { dds_copy_qos(qos_, other.qos_); }

Qos& Qos::operator=(const Qos& other) {
  if (this != &other) {
    dds_reset_qos(qos_);
    dds_copy_qos(qos_, other.qos_);
  }
  return *this;
}

// A moved-from Qos is empty but valid, so it can still be used or assigned.
Qos::Qos(Qos&& other) noexcept : qos_(std::exchange(other.qos_, dds_create_qos())) {}

Qos& Qos::operator=(Qos&& other) noexcept {
  std::swap(qos_, other.qos_);
  return *this;
}

Qos::~Qos() { dds_delete_qos(qos_); }

Qos& Qos::reliable(dds_duration_t max_blocking) {
  dds_qset_reliability(qos_, DDS_RELIABILITY_RELIABLE, max_blocking);
  return *this;
}

Qos& Qos::bestEffort() {
  dds_qset_reliability(qos_, DDS_RELIABILITY_BEST_EFFORT, 0);
  return *this;
}

Qos& Qos::keepLast(std::int32_t depth) {
  dds_qset_history(qos_, DDS_HISTORY_KEEP_LAST, depth);
  return *this;
}

Qos& Qos::keepAll() {
  dds_qset_history(qos_, DDS_HISTORY_KEEP_ALL, DDS_LENGTH_UNLIMITED);
  return *this;
}

Qos& Qos::transientLocal() {
  dds_qset_durability(qos_, DDS_DURABILITY_TRANSIENT_LOCAL);
  return *this;
}

Qos& Qos::volatile_() {
  dds_qset_durability(qos_, DDS_DURABILITY_VOLATILE);
  return *this;
}

Qos& Qos::xcdr1() {
  const dds_data_representation_id_t xcdr1 = DDS_DATA_REPRESENTATION_XCDR1;
  dds_qset_data_representation(qos_, 1, &xcdr1);
  return *this;
}

Qos& Qos::resourceLimits(std::int32_t max_samples, std::int32_t max_instances,
                         std::int32_t max_samples_per_instance) {
  dds_qset_resource_limits(qos_, max_samples, max_instances, max_samples_per_instance);
  return *this;
}

Qos& Qos::partition(const std::string& name) {
  dds_qset_partition1(qos_, name.c_str());
  return *this;
}

bool Qos::hasDataRepresentation() const {
  uint32_t n = 0;
  dds_data_representation_id_t* values = nullptr;
  const bool set = dds_qget_data_representation(qos_, &n, &values);
  dds_free(values);
  return set;
}

// --- Entity ---

Entity::Entity(dds_entity_t handle, const std::string& call) : handle_(check(handle, call)) {}

Entity& Entity::operator=(Entity&& other) noexcept {
  if (this != &other) {
    if (handle_ > 0) dds_delete(handle_);
    handle_ = std::exchange(other.handle_, 0);
  }
  return *this;
}

Entity::~Entity() {
  // Fails harmlessly if a parent was deleted first (which deleted this one).
  if (handle_ > 0) dds_delete(handle_);
}

Participant::Participant(dds_domainid_t domain_id)
    : Entity(dds_create_participant(domain_id, nullptr, nullptr),
             "dds_create_participant(domain " + std::to_string(domain_id) + ")") {}

// --- helpers behind the templates ---

namespace detail {

dds_entity_t createTopic(const Participant& participant, const std::string& name,
                         const dds_topic_descriptor_t& descriptor, const Qos& qos) {
  return check(
      dds_create_topic(participant.handle(), &descriptor, name.c_str(), qos.get(), nullptr),
      "dds_create_topic(\"" + name + "\", " + descriptor.m_typename + ")");
}

dds_entity_t createWriter(const Participant& participant, const Entity& topic, const Qos& qos) {
  const dds_qos_t* q = qos.get();
  Qos with_xcdr1;
  if (!qos.hasDataRepresentation()) {
    with_xcdr1 = qos;
    with_xcdr1.xcdr1();
    q = with_xcdr1.get();
  }
  return dds_create_writer(participant.handle(), topic.handle(), q, nullptr);
}

dds_entity_t createReader(const Participant& participant, const Entity& topic, const Qos& qos) {
  return dds_create_reader(participant.handle(), topic.handle(), qos.get(), nullptr);
}

bool write(dds_entity_t writer, const void* sample) {
  const dds_return_t rc = dds_write(writer, sample);
  if (rc == DDS_RETCODE_TIMEOUT) return false;
  check(rc, "dds_write");
  return true;
}

std::uint32_t matchedCount(dds_entity_t entity, bool publication) {
  if (publication) {
    dds_publication_matched_status_t status;
    check(dds_get_publication_matched_status(entity, &status),
          "dds_get_publication_matched_status");
    return status.current_count;
  }
  dds_subscription_matched_status_t status;
  check(dds_get_subscription_matched_status(entity, &status),
        "dds_get_subscription_matched_status");
  return status.current_count;
}

bool waitForMatched(dds_entity_t entity, bool publication, std::uint32_t count,
                    dds_duration_t timeout) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::nanoseconds(timeout);
  while (matchedCount(entity, publication) < count) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return true;
}

}  // namespace detail

// --- conditions and wait sets ---

ReadCondition::ReadCondition(const Entity& reader, std::uint32_t mask)
    : Entity(dds_create_readcondition(reader.handle(), mask), "dds_create_readcondition") {}

GuardCondition::GuardCondition(const Participant& participant)
    : Entity(dds_create_guardcondition(participant.handle()), "dds_create_guardcondition") {}

void GuardCondition::trigger() {
  check(dds_set_guardcondition(handle(), true), "dds_set_guardcondition");
}

void GuardCondition::reset() {
  check(dds_set_guardcondition(handle(), false), "dds_set_guardcondition");
}

bool GuardCondition::triggered() const {
  bool value = false;
  check(dds_read_guardcondition(handle(), &value), "dds_read_guardcondition");
  return value;
}

WaitSet::WaitSet(const Participant& participant)
    : Entity(dds_create_waitset(participant.handle()), "dds_create_waitset") {}

void WaitSet::attach(const Entity& condition, dds_attach_t cookie) {
  check(dds_waitset_attach(handle(), condition.handle(), cookie), "dds_waitset_attach");
}

void WaitSet::detach(const Entity& condition) {
  check(dds_waitset_detach(handle(), condition.handle()), "dds_waitset_detach");
}

bool WaitSet::wait(dds_duration_t timeout, std::vector<dds_attach_t>* triggered) {
  // Enough room for every cookie a wait set in this project attaches; if more
  // trigger, Cyclone reports the count and fills what fits.
  dds_attach_t cookies[16];
  const dds_return_t n =
      check(dds_waitset_wait(handle(), cookies, 16, timeout), "dds_waitset_wait");
  if (triggered != nullptr) {
    triggered->assign(cookies, cookies + std::min<dds_return_t>(n, 16));
  }
  return n > 0;
}

}  // namespace sl::dds
