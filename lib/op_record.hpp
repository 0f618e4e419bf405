#pragma once
// OpRecord: one submitted operation while it waits in a queue or runs; and the
// pool that recycles records, so submitting allocates nothing once warm.
#include <boost/lockfree/stack.hpp>

#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include "pdt/engine.hpp"

namespace pdt::detail {

struct OpRecord {
  OpKind kind = OpKind::insert;
  Point3 point;                 // insert: the point; removals: where the vertex is (routing)
  VertexId vertex = no_vertex;  // remove
  std::uint64_t stamp = 0;      // remove: the vertex incarnation expected (0 = any)
  std::uint64_t ticket = 0;     // insert: its own ticket; remove_insertion: the insertion undone
  bool from_batch = false;      // insert: part of a spatially sorted batch (walk from the last vertex)
  Engine::Callback done;
  OpAwaitBase* awaiter = nullptr;
};

// Records are allocated in slabs and recycled through a lock-free free list.
// Invariant: every record is either on the free list or owned by exactly one
// submitted operation (in a queue, parked on a ticket, or running).
class OpRecordPool {
 public:
  OpRecord* acquire();
  void release(OpRecord* op);  // resets the record and puts it back

 private:
  boost::lockfree::stack<OpRecord*> free_{1024};
  std::mutex slab_mutex_;
  std::vector<std::unique_ptr<OpRecord[]>> slabs_;
};

}  // namespace pdt::detail
