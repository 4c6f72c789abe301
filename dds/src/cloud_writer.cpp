// Cyclone DDS 0.10.2 as Debian builds it has shared memory (iceoryx) compiled
// in. That adds two pointers to the end of struct ddsi_serdata (iox_chunk,
// iox_subscriber) and two functions to the end of struct ddsi_serdata_ops,
// but the installed headers do not say so (DDS_HAS_SHM comes from a
// features.h that is not installed). Every dds_writecdr reads and clears
// iox_chunk: a serdata declared with the headers' default layout has Cyclone
// overwrite the first 8 bytes after it. So this file declares the larger
// layout. That is also right for a library built without shared memory: it
// then never reads past `twrite`, and the two extra functions stay null.
#define DDS_HAS_SHM 1
#include "sl/dds/cloud_writer.h"

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <optional>
#include <type_traits>
#include <vector>

#include <dds/ddsi/ddsi_serdata.h>
#include <dds/ddsi/ddsi_sertype.h>

namespace sl::dds {

namespace {

using PointCloud2 = CloudWriter::PointCloud2;
using Bytes = std::vector<unsigned char>;

// The probe's writer and reader meet only each other (README "Clouds
// written from their own memory").
constexpr const char* kProbePartition = "sl_internal_cloud_writer_probe";

// A cloud's serialized form, Cyclone's view first. The CDR bytes are
// prefix | points | suffix: prefix from the encapsulation header up to and
// including the data's length, suffix what follows the data (is_dense and
// the padding to 4 bytes).
struct BorrowedSample {
  ddsi_serdata c;
  Bytes prefix;
  const unsigned char* points = nullptr;
  std::size_t points_bytes = 0;
  Bytes suffix;
  std::uint32_t size = 0;
  std::shared_ptr<const void> owner;  // keeps `points` alive
};
static_assert(std::is_standard_layout_v<BorrowedSample>,
              "Cyclone's serdata must be at the start of BorrowedSample");

const BorrowedSample& sampleOf(const ddsi_serdata* d) {
  return *reinterpret_cast<const BorrowedSample*>(d);
}

// [off, off + sz) of the serialized sample in one piece, or null if it
// spans pieces (or runs past the end).
const unsigned char* contiguous(const BorrowedSample& b, std::size_t off, std::size_t sz) {
  const std::size_t p = b.prefix.size(), n = b.points_bytes;
  if (off + sz <= p) return b.prefix.data() + off;
  if (off >= p && off + sz <= p + n) return b.points + (off - p);
  if (off >= p + n && off + sz <= b.size) return b.suffix.data() + (off - p - n);
  return nullptr;
}

// Copies [off, off + sz) of the serialized sample; zeros past its end
// (Cyclone rounds fragment lengths up to 4 bytes).
void copyRange(const BorrowedSample& b, std::size_t off, std::size_t sz, unsigned char* out) {
  struct Piece {
    const unsigned char* data;
    std::size_t begin, end;
  };
  const std::size_t p = b.prefix.size(), n = b.points_bytes;
  const Piece pieces[3] = {{b.prefix.data(), 0, p}, {b.points, p, p + n}, {b.suffix.data(), p + n, b.size}};
  const std::size_t end = off + sz;
  std::memset(out, 0, sz);
  for (const Piece& piece : pieces) {
    const std::size_t lo = std::max(off, piece.begin), hi = std::min(end, piece.end);
    if (lo < hi) std::memcpy(out + (lo - off), piece.data + (lo - piece.begin), hi - lo);
  }
}

bool inside(const void* ptr, const void* base, std::size_t n) {
  const auto* p = static_cast<const unsigned char*>(ptr);
  const auto* b = static_cast<const unsigned char*>(base);
  return b != nullptr && p >= b && p < b + n;
}

// Copies made for a request spanning pieces of more than a fragment: a
// conversion to another sertype (which CloudWriter must never cause) or a
// local reader of another type. Fragments spanning two pieces are small.
std::atomic<std::uint64_t> g_large_copies{0};
constexpr std::size_t kLargeCopy = 1 << 20;

// ---- the serdata operations of a borrowed sample ----

std::uint32_t opGetSize(const ddsi_serdata* d) { return sampleOf(d).size; }

void opToSer(const ddsi_serdata* d, std::size_t off, std::size_t sz, void* buf) {
  copyRange(sampleOf(d), off, sz, static_cast<unsigned char*>(buf));
}

ddsi_serdata* opToSerRef(const ddsi_serdata* d, std::size_t off, std::size_t sz, ddsrt_iovec_t* ref) {
  const BorrowedSample& b = sampleOf(d);
  const unsigned char* piece = contiguous(b, off, sz);
  if (piece != nullptr) {
    ref->iov_base = const_cast<unsigned char*>(piece);
  } else {
    auto* copy = static_cast<unsigned char*>(std::malloc(std::max<std::size_t>(sz, 1)));
    if (copy == nullptr) {  // Cyclone has no error path here
      std::fputs("sl_sensord: out of memory copying a cloud fragment\n", stderr);
      std::abort();
    }
    copyRange(b, off, sz, copy);
    if (sz >= kLargeCopy) g_large_copies.fetch_add(1, std::memory_order_relaxed);
    ref->iov_base = copy;
  }
  ref->iov_len = static_cast<decltype(ref->iov_len)>(sz);
  return ddsi_serdata_ref(d);
}

void opToSerUnref(ddsi_serdata* d, const ddsrt_iovec_t* ref) {
  const BorrowedSample& b = sampleOf(d);
  if (!inside(ref->iov_base, b.prefix.data(), b.prefix.size()) &&
      !inside(ref->iov_base, b.points, b.points_bytes) &&
      !inside(ref->iov_base, b.suffix.data(), b.suffix.size()))
    std::free(ref->iov_base);
  ddsi_serdata_unref(d);
}

// A local reader's take: through a serdata of the type's own kind, made from
// the bytes (a copy; only readers in this process take this path).
bool opToSample(const ddsi_serdata* d, void* sample, void** bufptr, void* buflim) {
  const BorrowedSample& b = sampleOf(d);
  ddsrt_iovec_t iov[3];
  iov[0].iov_base = const_cast<unsigned char*>(b.prefix.data());
  iov[0].iov_len = static_cast<decltype(iov[0].iov_len)>(b.prefix.size());
  iov[1].iov_base = const_cast<unsigned char*>(b.points);
  iov[1].iov_len = static_cast<decltype(iov[1].iov_len)>(b.points_bytes);
  iov[2].iov_base = const_cast<unsigned char*>(b.suffix.data());
  iov[2].iov_len = static_cast<decltype(iov[2].iov_len)>(b.suffix.size());
  ddsi_serdata* plain = d->type->serdata_ops->from_ser_iov(d->type, SDK_DATA, 3, iov, b.size);
  if (plain == nullptr) return false;
  const bool ok = ddsi_serdata_to_sample(plain, sample, bufptr, buflim);
  ddsi_serdata_unref(plain);
  return ok;
}

// The key of a sample, which Cyclone keeps per instance (its key-to-instance
// map): the type is keyless (checked by the probe), so the key is the same
// empty one for every sample, with the bytes of Cyclone's own key sample.
// It must have this file's operations: the map tells keys of different
// operations apart, and one with Cyclone's would match its own instance's
// key but not a borrowed sample (Cyclone would then spin in the map's
// lookup, measured: the probe's write never returned).
ddsi_serdata* opToUntyped(const ddsi_serdata* d) {
  ddsi_keyhash_t none{};
  ddsi_serdata* key = d->type->serdata_ops->from_keyhash(d->type, &none);
  if (key == nullptr) return nullptr;
  auto* untyped = new BorrowedSample;
  ddsi_serdata_init(&untyped->c, d->type, SDK_KEY);
  untyped->c.ops = d->ops;
  untyped->c.type = nullptr;  // untyped, as Cyclone's
  untyped->c.hash = d->hash;
  untyped->prefix.resize(ddsi_serdata_size(key));
  ddsi_serdata_to_ser(key, 0, untyped->prefix.size(), untyped->prefix.data());
  untyped->size = static_cast<std::uint32_t>(untyped->prefix.size());
  ddsi_serdata_unref(key);
  return &untyped->c;
}

// A sample of the key alone (Cyclone's invalid samples, e.g. of an instance
// that lost its writer): keyless, so there is nothing to fill in.
bool opUntypedToSample(const ddsi_sertype*, const ddsi_serdata*, void*, void**, void*) { return true; }

bool opEqKey(const ddsi_serdata*, const ddsi_serdata*) { return true; }

void opGetKeyhash(const ddsi_serdata*, ddsi_keyhash* buf, bool) { std::memset(buf->value, 0, sizeof buf->value); }

void opFree(ddsi_serdata* d) { delete reinterpret_cast<BorrowedSample*>(d); }

std::size_t opPrint(const ddsi_sertype*, const ddsi_serdata* d, char* buf, std::size_t size) {
  const int n = std::snprintf(buf, size, "{PointCloud2, %zu data bytes borrowed}", sampleOf(d).points_bytes);
  return n < 0 ? 0 : std::min(static_cast<std::size_t>(n), size > 0 ? size - 1 : 0);
}

// One table for the process (samples may outlive any writer). The
// constructors from other forms are the type's own: Cyclone calls them
// through the type, never through a sample.
std::once_flag g_ops_once;
ddsi_serdata_ops g_ops{};
const ddsi_serdata_ops* g_base_ops = nullptr;

const ddsi_serdata_ops* borrowedOps(const ddsi_sertype* type) {
  std::call_once(g_ops_once, [type] {
    const ddsi_serdata_ops& base = *type->serdata_ops;
    g_base_ops = type->serdata_ops;
    g_ops.from_ser = base.from_ser;
    g_ops.from_ser_iov = base.from_ser_iov;
    g_ops.from_keyhash = base.from_keyhash;
    g_ops.from_sample = base.from_sample;
    g_ops.untyped_to_sample = opUntypedToSample;
    g_ops.eqkey = opEqKey;
    g_ops.get_size = opGetSize;
    g_ops.to_ser = opToSer;
    g_ops.to_ser_ref = opToSerRef;
    g_ops.to_ser_unref = opToSerUnref;
    g_ops.to_sample = opToSample;
    g_ops.to_untyped = opToUntyped;
    g_ops.free = opFree;
    g_ops.print = opPrint;
    g_ops.get_keyhash = opGetKeyhash;
    // get_sample_size, from_iox_buffer: null (never used for writing).
  });
  return type->serdata_ops == g_base_ops ? &g_ops : nullptr;
}

// ---- serialized forms ----

Bytes serialized(const ddsi_sertype* type, const PointCloud2& sample) {
  ddsi_serdata* d = ddsi_serdata_from_sample(type, SDK_DATA, &sample);
  if (d == nullptr) return {};
  Bytes bytes(ddsi_serdata_size(d));
  ddsi_serdata_to_ser(d, 0, bytes.size(), bytes.data());
  ddsi_serdata_unref(d);
  return bytes;
}

struct Around {
  Bytes prefix, suffix;
};

// The serialized form of `sample` around its data, found by serializing it
// with r and r + 4 stand-in data bytes (r = its length mod 4, so that every
// alignment after the data is the same): the first byte that differs lies in
// the data's length. Checks that the two differ only there and by the data;
// nullopt if not (then the sample is not shaped as this writer assumes).
std::optional<Around> serializedAround(const ddsi_sertype* type, const PointCloud2& sample) {
  const std::uint64_t n = sample.data._length;
  const std::uint32_t r = static_cast<std::uint32_t>(n % 4);
  unsigned char stand_in[8] = {};
  PointCloud2 m = sample;
  m.data._buffer = stand_in;
  m.data._release = false;
  m.data._length = m.data._maximum = r;
  const Bytes a = serialized(type, m);
  m.data._length = m.data._maximum = r + 4;
  const Bytes b = serialized(type, m);
  if (a.size() < 8 || b.size() != a.size() + 4) return std::nullopt;
  const std::size_t first = static_cast<std::size_t>(std::mismatch(a.begin(), a.end(), b.begin()).first - a.begin());
  if (first < 4 || first >= a.size()) return std::nullopt;  // not past the encapsulation header
  // CDR offsets count from after the 4-byte encapsulation header; a length
  // is 4-byte aligned.
  const std::size_t at = 4 + ((first - 4) & ~std::size_t{3});
  const bool little = (a[1] & 1) != 0;  // CDR_LE, PL_CDR_LE, CDR2_LE, ... are odd
  auto lengthAt = [little](const Bytes& bytes, std::size_t i) {
    std::uint32_t v = 0;
    for (int k = 0; k < 4; ++k)
      v |= static_cast<std::uint32_t>(bytes[i + (little ? k : 3 - k)]) << (8 * k);
    return v;
  };
  if (at + 4 + r > a.size() || lengthAt(a, at) != r || lengthAt(b, at) != r + 4) return std::nullopt;
  if (!std::equal(a.begin() + static_cast<std::ptrdiff_t>(at + 4 + r), a.end(),
                  b.begin() + static_cast<std::ptrdiff_t>(at + 8 + r)))
    return std::nullopt;
  Around around;
  around.prefix.assign(a.begin(), a.begin() + static_cast<std::ptrdiff_t>(at + 4));
  const std::uint32_t len = static_cast<std::uint32_t>(n);
  for (int k = 0; k < 4; ++k)
    around.prefix[at + (little ? k : 3 - k)] = static_cast<unsigned char>(len >> (8 * k));
  around.suffix.assign(a.begin() + static_cast<std::ptrdiff_t>(at + 4 + r), a.end());
  return around;
}

// A new serdata (one reference) of `sample` borrowing its data; null if the
// sample is not shaped as assumed or too large for a serdata's size.
BorrowedSample* borrow(const ddsi_sertype* type, const ddsi_serdata_ops* ops, const PointCloud2& sample,
                       std::shared_ptr<const void> owner) {
  std::optional<Around> around = serializedAround(type, sample);
  if (!around) return nullptr;
  const std::uint64_t size =
      std::uint64_t{around->prefix.size()} + sample.data._length + around->suffix.size();
  if (size > UINT32_MAX - 64) return nullptr;
  auto* b = new BorrowedSample;
  ddsi_serdata_init(&b->c, type, SDK_DATA);
  b->c.ops = ops;
  b->c.hash = type->serdata_basehash;  // keyless: as Cyclone's own serdata
  b->prefix = std::move(around->prefix);
  b->suffix = std::move(around->suffix);
  b->points = sample.data._buffer;
  b->points_bytes = sample.data._length;
  b->size = static_cast<std::uint32_t>(size);
  b->owner = std::move(owner);
  return b;
}

// A 3 x 1 probe cloud; `tag` makes two of them different.
struct ProbeCloud {
  explicit ProbeCloud(float tag) {
    for (int i = 0; i < 12; ++i) values[i] = tag + static_cast<float>(i);
    static char x[] = "x", y[] = "y", z[] = "z", in[] = "intensity";
    char* names[4] = {x, y, z, in};
    for (std::uint32_t i = 0; i < 4; ++i) fields[i] = {names[i], 4 * i, 7, 1};
    msg.header.stamp = {1, 2};
    msg.header.frame_id = frame;
    msg.height = 1;
    msg.width = 3;
    msg.fields = {4, 4, fields, false};
    msg.point_step = 16;
    msg.row_step = 48;
    msg.data = {48, 48, reinterpret_cast<std::uint8_t*>(values), false};
    msg.is_dense = true;
  }
  float values[12];
  sensor_msgs_msg_dds__PointField_ fields[4];
  char frame[6] = "probe";
  PointCloud2 msg{};
};

// Takes one sample serialized from `reader`; null if none.
ddsi_serdata* takeSerialized(dds_entity_t reader) {
  ddsi_serdata* d = nullptr;
  dds_sample_info_t info;
  return dds_takecdr(reader, &d, 1, &info, DDS_ANY_STATE) == 1 ? d : nullptr;
}

}  // namespace

struct CloudWriter::Borrowed {
  const ddsi_sertype* type = nullptr;
  const ddsi_serdata_ops* ops = nullptr;
};

namespace {

// Whether a writer of `topic` with `qos` can send borrowed clouds: empty if
// so (and *type, *ops set), else why not.
std::string probe(const dds::Participant& participant, const dds::Topic<PointCloud2>& topic,
                  const dds::Qos& qos, const ddsi_sertype** type, const ddsi_serdata_ops** ops) {
  dds::Qos writer_qos = qos;
  writer_qos.partition(kProbePartition);
  dds::Writer<PointCloud2> writer(participant, topic, writer_qos);
  dds::Reader<PointCloud2> reader(participant, topic,
                                  dds::Qos().reliable().keepLast(2).partition(kProbePartition));
  // The type Cyclone serializes this topic's samples with.
  ProbeCloud plain(1.0f);
  if (!writer.write(plain.msg)) return "the probe's write timed out";
  ddsi_serdata* first = takeSerialized(reader.handle());
  if (first == nullptr) return "the probe's reader got no sample";
  *type = first->type;
  ddsi_serdata_unref(first);
  if (!(*type)->typekind_no_key) return "the type has a key";
  *ops = borrowedOps(*type);
  if (*ops == nullptr) return "the type's serialization differs from the first one seen";
  // A borrowed sample must reach the reader as written: not converted (a
  // copy), and with the bytes dds_write gives.
  ProbeCloud other(100.0f);
  BorrowedSample* b = borrow(*type, *ops, other.msg, nullptr);
  if (b == nullptr) return "a PointCloud2 does not serialize as assumed (data length, then the data)";
  const dds_return_t rc = dds_writecdr(writer.handle(), &b->c);
  if (rc != DDS_RETCODE_OK) return "dds_writecdr failed: " + std::string(dds_strretcode(rc));
  ddsi_serdata* got = takeSerialized(reader.handle());
  if (got == nullptr) return "the probe's reader got no borrowed sample";
  std::string why;
  if (got->ops != *ops) why = "Cyclone converted the borrowed sample (the writer's type differs)";
  Bytes bytes(ddsi_serdata_size(got));
  ddsi_serdata_to_ser(got, 0, bytes.size(), bytes.data());
  if (why.empty() && bytes != serialized(*type, other.msg))
    why = "the borrowed sample's bytes differ from dds_write's";
  PointCloud2 back{};
  if (why.empty()) {
    if (!ddsi_serdata_to_sample(got, &back, nullptr, nullptr) || back.data._length != 48 ||
        std::memcmp(back.data._buffer, other.values, 48) != 0 || back.width != 3)
      why = "the borrowed sample does not read back";
    dds_sample_free(&back, &sensor_msgs_msg_dds__PointCloud2__desc, DDS_FREE_CONTENTS);
  }
  ddsi_serdata_unref(got);
  return why;
}

}  // namespace

CloudWriter::CloudWriter(const dds::Participant& participant, const dds::Topic<PointCloud2>& topic,
                         const dds::Qos& qos, std::string serialize_reason)
    : writer_(participant, topic, qos), why_not_(std::move(serialize_reason)) {
  if (!why_not_.empty()) return;
  auto borrowed = std::make_unique<Borrowed>();
  try {
    why_not_ = probe(participant, topic, qos, &borrowed->type, &borrowed->ops);
  } catch (const std::exception& e) {  // e.g. DDS Security not permitting the probe
    why_not_ = std::string("its probe failed: ") + e.what();
  }
  if (why_not_.empty()) borrowed_ = std::move(borrowed);
}

CloudWriter::~CloudWriter() = default;

bool CloudWriter::borrowing() const { return borrowed_ != nullptr; }
const std::string& CloudWriter::whyNotBorrowing() const { return why_not_; }

bool CloudWriter::write(const PointCloud2& sample, std::shared_ptr<const void> owner) {
  if (!borrowed_) return writer_.write(sample);
  BorrowedSample* b = borrow(borrowed_->type, borrowed_->ops, sample, std::move(owner));
  if (b == nullptr) return writer_.write(sample);  // not the shape the probe checked: copy
  const dds_return_t rc = dds_writecdr(writer_.handle(), &b->c);  // takes the reference
  if (rc == DDS_RETCODE_TIMEOUT) return false;
  dds::check(rc, "dds_writecdr");
  return true;
}

std::string CloudWriter::borrowedBytes(const PointCloud2& sample) const {
  if (!borrowed_) return {};
  BorrowedSample* b = borrow(borrowed_->type, borrowed_->ops, sample, nullptr);
  if (b == nullptr) return {};
  std::string bytes(b->size, '\0');
  ddsi_serdata_to_ser(&b->c, 0, bytes.size(), bytes.data());
  ddsi_serdata_unref(&b->c);
  return bytes;
}

std::uint64_t CloudWriter::largeCopies() { return g_large_copies.load(std::memory_order_relaxed); }

}  // namespace sl::dds
