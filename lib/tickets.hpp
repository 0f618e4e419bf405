#pragma once
// Tickets: insertion t of an engine is ticket t. Its slot records the
// insertion's outcome once it is done, so that remove_insertion(t) can find
// the vertex to remove, and lets an undo that arrives first wait for it.
//
// The park handshake (an undo before its insertion is done) is a Dekker
// handshake between state and parked: the undo stores parked then reads
// state; the insertion stores state then exchanges parked; all seq_cst. So
// at least one side sees the other, and `exchange` decides who re-queues.
#include <oneapi/tbb/concurrent_vector.h>

#include <atomic>
#include <cstdint>
#include <exception>
#include <span>

#include "op_record.hpp"

namespace pdt::detail {

enum class TicketState : int { pending, inserted, failed };

struct TicketSlot {
  std::atomic<TicketState> state{TicketState::pending};
  std::atomic<bool> undone{false};  // an undo was claimed (submitted) for it
  std::atomic<OpRecord*> parked{nullptr};  // an undo waiting for the insertion
  VertexId vertex = no_vertex;  // written before state becomes inserted
  bool inserted = false;        // same
  std::uint64_t stamp = 0;      // same: the vertex incarnation
  std::exception_ptr error;     // written before state becomes failed
  Point3 point;                 // written when issued: where the undo is routed
};

class TicketTable {
 public:
  // Issues tickets for points (one each, consecutive); returns the first.
  std::uint64_t issue(std::span<const Point3> points);
  std::uint64_t size() const { return slots_.size(); }
  TicketSlot& operator[](std::uint64_t t) { return slots_[t]; }
  const TicketSlot& operator[](std::uint64_t t) const { return slots_[t]; }

  // Marks insertion t as undone; throws pdt::Error(unknown_vertex) for a
  // ticket never issued or already undone. unclaim gives a claim back.
  void claim_undo(std::uint64_t t);
  void unclaim_undo(std::uint64_t t) { slots_[t].undone.store(false); }
  // The outcome of a finished insertion (rethrows its error); throws
  // pdt::Error(invalid_argument) if t was never issued or is not finished.
  InsertResult result(std::uint64_t t) const;

  // An undo of t found it pending: parks it. Returns the undo back when the
  // insertion finished meanwhile (the caller runs it), else nullptr.
  OpRecord* park(std::uint64_t t, OpRecord* undo);
  // Records insertion t's outcome; returns an undo parked on it, to re-queue.
  OpRecord* finish_inserted(std::uint64_t t, InsertResult r, std::uint64_t stamp);
  OpRecord* finish_failed(std::uint64_t t, std::exception_ptr error);

 private:
  tbb::concurrent_vector<TicketSlot> slots_;
};

}  // namespace pdt::detail
