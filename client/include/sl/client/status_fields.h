// The engine's status counters and measurements, listed once: the fields of
// ros2/sl_msgs/msg/Status.msg that the engine fills (daemon EngineStatus) and
// that travel unchanged to the client (StatusInfo). Each consumer expands
// the list instead of naming the fields:
//   EngineStatus and StatusInfo members   (sl/daemon/scan_engine.h, client.h)
//   EngineStatus -> Status sample         (daemon/src/ros_messages.cpp)
//   Status sample -> StatusInfo           (client/src/client.cpp)
//   /diagnostics pipeline key/values      (daemon/src/ros_graph.cpp, key = name)
//   `slctl status` lines                  (tools/slctl/slctl.cpp: a "label: value"
//                                          line for each field it does not format itself)
// test_messages checks the list against Status.msg, both ways.
//
// Fields that are not here are written by hand: the state, strings, lists,
// times and enums, sets_dropped (the engine's drops plus the edge's timed-out
// writes) and the DDS edge's counters (requests_*, replies_timed_out,
// writes_timed_out, clouds_lost_to_readers, points_readers).
//
// X(type, name, label): `type` std::uint64_t (Status.msg uint64) or double
// (float64); `name` the field's name everywhere; `label` a short
// description, for people (slctl). Status.msg's comment is the field's
// documentation; units there.
#pragma once

#include <cstdint>

#define SL_STATUS_ENGINE_FIELDS(X)                                                              \
  /* Of the current / last request. */                                                          \
  X(std::uint64_t, scans_done, "scans done")                                                    \
  X(std::uint64_t, scans_requested, "scans requested (0: continuous)")                          \
  X(double, scan_rate_hz, "scan rate [Hz]")     /* clouds per second, smoothed */               \
  X(double, frame_rate_hz, "frame rate [Hz]")   /* camera frames per second, all cameras */     \
  X(std::uint64_t, frames_received, "frames received") /* since start-up, all cameras */         \
  /* Drops since start-up (frames_dropped = frames_overflow + frames_unmatched). */             \
  X(std::uint64_t, frames_dropped, "frames dropped")                                            \
  X(std::uint64_t, sets_incomplete, "sets incomplete") /* purged or abandoned, frames missing */ \
  X(std::uint64_t, frames_overflow, "frames dropped: queue full") /* oldest dropped */          \
  X(std::uint64_t, frames_unmatched, "frames dropped: unmatched") /* no trigger window */        \
  X(std::uint64_t, sets_overflow, "sets dropped: queue full")   /* a set or result queue */     \
  X(std::uint64_t, sets_not_recorded, "sets not recorded")      /* the recorder fell behind */  \
  /* Recording, since start-up. */                                                              \
  X(std::uint64_t, sets_recorded, "sets recorded")                                              \
  X(std::uint64_t, sets_over_quota, "sets over quota") /* not recorded: quota reached */        \
  X(std::uint64_t, errors_reported, "errors reported") /* every error since start-up */         \
  /* [ms] latency over the last (up to 64) published scans: median, maximum, stage medians. */ \
  X(double, latency_ms, "latency median [ms]")                                                  \
  X(double, latency_max_ms, "latency max [ms]")                                                 \
  X(double, wait_ms, "latency: wait [ms]")                                                      \
  X(double, processing_ms, "latency: processing [ms]")                                          \
  X(double, publish_ms, "latency: publishing [ms]")                                             \
  /* Decode health of the latest scan, first camera (docs/decode-health.md). */                 \
  X(double, decode_modulated_fraction, "decode: modulated fraction")                            \
  X(double, decode_consistent_fraction, "decode: consistent fraction")                          \
  X(double, decode_residual_median, "decode: residual median [periods]")                        \
  X(std::uint64_t, clouds_implausible, "clouds implausible") /* not published, since start-up */ \
  X(std::uint64_t, adaptive_switches, "adaptive switches")   /* adaptive mode changes, since start-up */

// Declares the fields as members, each zero.
#define SL_STATUS_DECLARE_FIELD(type, name, label) type name = 0;
