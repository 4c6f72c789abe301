// Small RAII layer over the Cyclone DDS C API (0.10).
//
// Entities (Participant, Topic, Writer, Reader, ReadCondition, GuardCondition,
// WaitSet) are move-only owners of a dds_entity_t and dds_delete() it on
// destruction. Deleting a parent deletes its children inside Cyclone; the
// child's later dds_delete() then fails harmlessly, so destruction order does
// not matter for correctness (declare parents first anyway).
//
// Thread safety: Cyclone entities are thread-safe, so one Writer may be used
// from several threads and a GuardCondition may be triggered from any thread
// while another waits on a WaitSet. The wrapper objects themselves are
// thread-compatible (moving or destroying one while another thread uses it is
// a race). Qos and Loan are plain values, thread-compatible.
//
// Errors: creation failures and misuse throw sl::dds::Error. A reliable write
// that times out because readers do not keep up is a normal per-sample event
// and is reported by Writer::write() returning false.
//
// Configuration: Cyclone reads its XML configuration from the CYCLONEDDS_URI
// environment variable when the first participant of a domain is created
// (e.g. CYCLONEDDS_URI=file:///.../config/cyclonedds-loopback.xml).
#pragma once

#include <dds/dds.h>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace sl::dds {

// A failed Cyclone call: what() names the call (with context) and the
// dds_strretcode() text, e.g. "dds_create_topic(\"a b\"): Bad Parameter (-3)".
class Error : public std::runtime_error {
 public:
  Error(const std::string& call, dds_return_t code);
  dds_return_t code() const { return code_; }

 private:
  dds_return_t code_;
};

// Throws Error(call, rc) if rc < 0 (Cyclone's convention for entities and
// return codes alike); returns rc otherwise.
dds_return_t check(dds_return_t rc, const std::string& call);

// Makes the process keep the memory of freed large samples for the next
// ones instead of giving it back to the kernel, where each 25 MB cloud would
// be page-faulted in again (~6,100 faults per cloud; README "DDS
// deployment"). glibc's allocator serves blocks above its mmap threshold
// (128 KiB, raised dynamically up to 32 MiB) with mmap and unmaps them on
// free, trims the main heap's free top, and unmaps a thread heap that
// becomes empty; this sets, for the whole process:
//   M_MMAP_THRESHOLD 32 MiB  blocks up to 32 MiB come from the heaps
//   M_TRIM_THRESHOLD 2 GiB   the main heap's free top is kept
//   M_TOP_PAD 64 MiB         thread heaps keep 64 MiB (a whole heap) free
// The cost is that the peak stays resident (bounded by the peak, as the
// writers' and readers' histories are bounded). Call once at the start of
// main, before threads allocate; the same settings can be given to any
// other process as GLIBC_TUNABLES (README, "Memory of large samples").
// Returns false if glibc
// refused one of them. SL_DEFAULT_MALLOC=1 in the environment leaves glibc's
// defaults (to measure the difference).
bool retainLargeSampleMemory();

// Touches `count` blocks of `block_bytes` (each below retainLargeSampleMemory's
// 32 MiB mmap threshold, else nothing is done) in the calling thread's heap
// and frees them: with retainLargeSampleMemory's settings the memory stays
// with the thread's malloc arena, so the thread's first large buffers
// (clouds, images, samples taken) do not page-fault. On a VM that hands
// free memory back to the host a first touch is costly (docs/measurements.md).
void prefaultHeap(std::size_t block_bytes, std::size_t count);

// Makes the process's shared-memory mappings (/dev/shm: iceoryx's segments
// when the Cyclone DDS configuration enables shared memory) cheap to use:
// fills in their page tables, writable where the mapping is (madvise
// MADV_POPULATE_WRITE / _READ, Linux >= 5.14), then reads one byte of every
// page. Contents are not changed. Both steps are needed on this project's
// VM: without the first, each page faults at its first use; after it, the
// first access of each page by each process still costs the hypervisor
// time (shadow page tables filled in on access, invisible to the guest's
// fault counters; docs/measurements.md, "Shared memory first access") per cloud
// written into, or taken from, a chunk this process had not used. Chunks
// come into use long after START (when a reader stops taking and holds
// some), so a local reader's clouds were late then. The read pass costs
// time once at start, in proportion to the segments' size.
// Call after the participant's readers and writers exist (the segments are
// mapped by then). Returns the bytes populated: 0 without shared memory.
std::size_t populateSharedMemoryMappings();

// Owning, copyable QoS policy set. An empty Qos leaves every policy at
// Cyclone's default. Builders return *this so they chain:
//   Qos().reliable(DDS_MSECS(500)).keepLast(1).xcdr1()
class Qos {
 public:
  Qos();
  Qos(const Qos& other);
  Qos& operator=(const Qos& other);
  Qos(Qos&& other) noexcept;
  Qos& operator=(Qos&& other) noexcept;
  ~Qos();

  // Reliable delivery; a write blocks at most max_blocking (ns) when the
  // writer's unacknowledged data exceeds its limit, then returns a timeout.
  Qos& reliable(dds_duration_t max_blocking = DDS_MSECS(100));
  Qos& bestEffort();
  Qos& keepLast(std::int32_t depth);
  Qos& keepAll();
  // Writer keeps its history for late-joining readers (needs a reliable,
  // transient-local reader to take effect).
  Qos& transientLocal();
  Qos& volatile_();
  // Data representation XCDR1 only, as ROS 2 uses (a reader with this QoS
  // accepts only XCDR1 writers).
  Qos& xcdr1();
  // The one partition the entity is in (default: the default partition "").
  Qos& partition(const std::string& name);
  // DDS_LENGTH_UNLIMITED (-1) for "no limit".
  Qos& resourceLimits(std::int32_t max_samples, std::int32_t max_instances,
                      std::int32_t max_samples_per_instance);

  const dds_qos_t* get() const { return qos_; }
  // True if the data representation policy is set.
  bool hasDataRepresentation() const;

 private:
  dds_qos_t* qos_;
};

// Base of all entity wrappers: a move-only owned handle.
class Entity {
 public:
  Entity(const Entity&) = delete;
  Entity& operator=(const Entity&) = delete;
  Entity(Entity&& other) noexcept : handle_(std::exchange(other.handle_, 0)) {}
  Entity& operator=(Entity&& other) noexcept;
  ~Entity();

  dds_entity_t handle() const { return handle_; }

 protected:
  Entity() = default;
  // Takes ownership of the result of a dds_create_*() call; throws Error if
  // it is an error code.
  Entity(dds_entity_t handle, const std::string& call);

 private:
  dds_entity_t handle_ = 0;
};

class Participant : public Entity {
 public:
  // domain_id 0..232 (ports must fit; DDS_DOMAIN_DEFAULT: the configuration's domain, 0 if
  // none). Throws Error for an invalid id or a broken configuration.
  explicit Participant(dds_domainid_t domain_id = DDS_DOMAIN_DEFAULT);
};

namespace detail {
dds_entity_t createTopic(const Participant& participant, const std::string& name,
                         const dds_topic_descriptor_t& descriptor, const Qos& qos);
dds_entity_t createWriter(const Participant& participant, const Entity& topic, const Qos& qos);
dds_entity_t createReader(const Participant& participant, const Entity& topic, const Qos& qos);
bool write(dds_entity_t writer, const void* sample);
std::uint32_t matchedCount(dds_entity_t entity, bool publication);
bool waitForMatched(dds_entity_t entity, bool publication, std::uint32_t count,
                    dds_duration_t timeout);
}  // namespace detail

// A topic whose samples are the idlc-generated C struct T, described by
// descriptor (e.g. Topic<sensor_msgs_msg_dds__PointCloud2_>(p, "rt/sl/points",
// sensor_msgs_msg_dds__PointCloud2__desc)). The descriptor must outlive the
// topic (the generated ones are static).
template <typename T>
class Topic : public Entity {
 public:
  Topic(const Participant& participant, const std::string& name,
        const dds_topic_descriptor_t& descriptor, const Qos& qos = Qos())
      : Entity(detail::createTopic(participant, name, descriptor, qos), "dds_create_topic") {}
};

template <typename T>
class Writer : public Entity {
 public:
  // If qos does not set a data representation, XCDR1 is added: every writer
  // publishes XCDR1, which ROS 2 readers expect.
  Writer(const Participant& participant, const Topic<T>& topic, const Qos& qos = Qos())
      : Entity(detail::createWriter(participant, topic, qos), "dds_create_writer") {}

  // Serializes and sends sample (the caller keeps ownership). Returns false if
  // a reliable writer timed out (max_blocking) waiting for slow readers: the
  // sample was not sent. Throws Error for any other failure.
  bool write(const T& sample) { return detail::write(handle(), &sample); }

  // Number of readers currently matched (publication matched status).
  std::uint32_t matchedReaders() const { return detail::matchedCount(handle(), true); }
  // Polls until at least count readers are matched; false on timeout (ns).
  bool waitForReaders(std::uint32_t count, dds_duration_t timeout) const {
    return detail::waitForMatched(handle(), true, count, timeout);
  }
};

// Samples taken from a Reader, on loan from Cyclone: no copy beyond the
// deserialization Cyclone does anyway (a 25 MB cloud is deserialized once,
// into the loaned buffer, and never copied again). Move-only; the loan goes
// back to the reader on destruction, so a Loan must not outlive its Reader.
// Samples whose info(i).valid_data is false carry no data (e.g. the last
// writer went away); check isValid(i) before using operator[].
template <typename T>
class Loan {
 public:
  Loan() = default;
  Loan(const Loan&) = delete;
  Loan& operator=(const Loan&) = delete;
  Loan(Loan&& other) noexcept
      : reader_(other.reader_),
        samples_(std::move(other.samples_)),
        infos_(std::move(other.infos_)),
        count_(std::exchange(other.count_, 0)) {}
  Loan& operator=(Loan&& other) noexcept {
    if (this != &other) {
      release();
      reader_ = other.reader_;
      samples_ = std::move(other.samples_);
      infos_ = std::move(other.infos_);
      count_ = std::exchange(other.count_, 0);
    }
    return *this;
  }
  ~Loan() { release(); }

  std::size_t size() const { return count_; }
  bool empty() const { return count_ == 0; }
  const T& operator[](std::size_t i) const { return *static_cast<const T*>(samples_[i]); }
  const dds_sample_info_t& info(std::size_t i) const { return infos_[i]; }
  bool isValid(std::size_t i) const { return infos_[i].valid_data; }

  // Returns the samples to the reader now (also done by the destructor).
  void release() {
    if (count_ > 0) {
      dds_return_loan(reader_, samples_.data(), static_cast<std::int32_t>(count_));
      count_ = 0;
    }
  }

 private:
  template <typename>
  friend class Reader;

  dds_entity_t reader_ = 0;
  std::vector<void*> samples_;
  std::vector<dds_sample_info_t> infos_;
  std::size_t count_ = 0;
};

template <typename T>
class Reader : public Entity {
 public:
  Reader(const Participant& participant, const Topic<T>& topic, const Qos& qos = Qos())
      : Entity(detail::createReader(participant, topic, qos), "dds_create_reader") {}

  // Takes up to max_samples (>= 1) samples without blocking; an empty Loan
  // if there are none.
  Loan<T> take(std::size_t max_samples = 1) {
    Loan<T> loan;
    if (max_samples == 0) return loan;
    loan.reader_ = handle();
    loan.samples_.assign(max_samples, nullptr);  // null: Cyclone lends the memory
    loan.infos_.resize(max_samples);
    const dds_return_t n = check(dds_take(handle(), loan.samples_.data(), loan.infos_.data(),
                                          max_samples, static_cast<std::uint32_t>(max_samples)),
                                 "dds_take");
    loan.count_ = static_cast<std::size_t>(n);
    return loan;
  }

  // Number of writers currently matched (subscription matched status).
  std::uint32_t matchedWriters() const { return detail::matchedCount(handle(), false); }
  bool waitForWriters(std::uint32_t count, dds_duration_t timeout) const {
    return detail::waitForMatched(handle(), false, count, timeout);
  }
};

// Triggers while reader has samples in any of the states in mask (default:
// any sample at all). Attach it to a WaitSet to wait for data.
class ReadCondition : public Entity {
 public:
  explicit ReadCondition(const Entity& reader, std::uint32_t mask = DDS_ANY_STATE);
};

// A condition set by the application, typically to wake a thread blocked in
// WaitSet::wait() for shutdown. trigger() may be called from any thread.
class GuardCondition : public Entity {
 public:
  explicit GuardCondition(const Participant& participant);
  void trigger();
  void reset();
  bool triggered() const;
};

class WaitSet : public Entity {
 public:
  explicit WaitSet(const Participant& participant);

  // cookie is reported back by wait() for the conditions that triggered.
  void attach(const Entity& condition, dds_attach_t cookie = 0);
  void detach(const Entity& condition);

  // Blocks until an attached condition triggers or timeout (ns, relative;
  // DDS_INFINITY to wait forever) expires. Returns true if something
  // triggered; then *triggered (if given) holds the triggered cookies.
  bool wait(dds_duration_t timeout, std::vector<dds_attach_t>* triggered = nullptr);
};

}  // namespace sl::dds
