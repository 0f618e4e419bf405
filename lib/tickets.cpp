#include "tickets.hpp"

#include <string>

#include "pdt/error.hpp"

namespace pdt::detail {

std::uint64_t TicketTable::issue(std::span<const Point3> points) {
  auto it = slots_.grow_by(points.size());
  const auto first = static_cast<std::uint64_t>(it - slots_.begin());
  for (std::size_t i = 0; i < points.size(); ++i) slots_[first + i].point = points[i];
  return first;
}

void TicketTable::claim_undo(std::uint64_t t) {
  if (t >= slots_.size())
    throw Error(ErrorCode::unknown_vertex, "cannot undo insertion " + std::to_string(t) + ": no such insertion was submitted");
  if (slots_[t].undone.exchange(true))
    throw Error(ErrorCode::unknown_vertex, "cannot undo insertion " + std::to_string(t) + ": it was already undone");
}

InsertResult TicketTable::result(std::uint64_t t) const {
  if (t >= slots_.size())
    throw Error(ErrorCode::invalid_argument, "insertion " + std::to_string(t) + " was never submitted");
  const TicketSlot& slot = slots_[t];
  switch (slot.state.load(std::memory_order_acquire)) {
    case TicketState::inserted: return {slot.vertex, slot.inserted};
    case TicketState::failed: std::rethrow_exception(slot.error);
    case TicketState::pending: break;
  }
  throw Error(ErrorCode::invalid_argument,
              "insertion " + std::to_string(t) + " has not finished; drain() first, or wait for its callback");
}

OpRecord* TicketTable::park(std::uint64_t t, OpRecord* undo) {
  TicketSlot& slot = slots_[t];
  slot.parked.store(undo, std::memory_order_seq_cst);
  if (slot.state.load(std::memory_order_seq_cst) == TicketState::pending) return nullptr;
  // Done meanwhile: take it back, unless the completion already did.
  return slot.parked.exchange(nullptr, std::memory_order_seq_cst);
}

OpRecord* TicketTable::finish_inserted(std::uint64_t t, InsertResult r, std::uint64_t stamp) {
  TicketSlot& slot = slots_[t];
  slot.vertex = r.vertex;
  slot.inserted = r.inserted;
  slot.stamp = stamp;
  slot.state.store(TicketState::inserted, std::memory_order_seq_cst);
  return slot.parked.exchange(nullptr, std::memory_order_seq_cst);
}

OpRecord* TicketTable::finish_failed(std::uint64_t t, std::exception_ptr error) {
  TicketSlot& slot = slots_[t];
  slot.error = std::move(error);
  slot.state.store(TicketState::failed, std::memory_order_seq_cst);
  return slot.parked.exchange(nullptr, std::memory_order_seq_cst);
}

}  // namespace pdt::detail
