#include "op_record.hpp"

namespace pdt::detail {

OpRecord* OpRecordPool::acquire() {
  OpRecord* op = nullptr;
  if (free_.pop(op)) return op;
  constexpr std::size_t slab = 4096;
  std::lock_guard lock(slab_mutex_);
  slabs_.push_back(std::make_unique<OpRecord[]>(slab));
  OpRecord* s = slabs_.back().get();
  for (std::size_t i = 1; i < slab; ++i) free_.push(&s[i]);
  return &s[0];
}

void OpRecordPool::release(OpRecord* op) {
  op->done = nullptr;
  op->awaiter = nullptr;
  op->from_batch = false;
  free_.push(op);
}

}  // namespace pdt::detail
