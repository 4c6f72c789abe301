// Small RAII helpers over the glib / Aravis C API (private to sl_drivers).
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>

#include <arv.h>

namespace sl::drivers::aravis {

// Owns one GObject reference.
template <typename T>
class GObjectPtr {
 public:
  GObjectPtr() = default;
  explicit GObjectPtr(T* p) : p_(p) {}
  ~GObjectPtr() { reset(); }
  GObjectPtr(GObjectPtr&& o) noexcept : p_(o.p_) { o.p_ = nullptr; }
  GObjectPtr& operator=(GObjectPtr&& o) noexcept {
    if (this != &o) {
      reset();
      p_ = o.p_;
      o.p_ = nullptr;
    }
    return *this;
  }
  GObjectPtr(const GObjectPtr&) = delete;
  GObjectPtr& operator=(const GObjectPtr&) = delete;
  void reset(T* p = nullptr) {
    if (p_ != nullptr) g_object_unref(p_);
    p_ = p;
  }
  T* get() const { return p_; }
  explicit operator bool() const { return p_ != nullptr; }

 private:
  T* p_ = nullptr;
};

// Owns a GError filled through out().
class GErrorPtr {
 public:
  GErrorPtr() = default;
  ~GErrorPtr() { reset(); }
  GErrorPtr(const GErrorPtr&) = delete;
  GErrorPtr& operator=(const GErrorPtr&) = delete;
  GError** out() {
    reset();
    return &e_;
  }
  void reset() {
    if (e_ != nullptr) g_error_free(e_);
    e_ = nullptr;
  }
  explicit operator bool() const { return e_ != nullptr; }
  std::string message() const { return e_ != nullptr ? e_->message : ""; }

 private:
  GError* e_ = nullptr;
};

inline std::string str(const char* s) { return s != nullptr ? s : ""; }

inline std::string hex(std::uint32_t v) {
  char b[16];
  std::snprintf(b, sizeof b, "0x%08x", v);
  return b;
}

}  // namespace sl::drivers::aravis
