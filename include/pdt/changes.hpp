// SPDX-License-Identifier: MIT
#pragma once
// What an operation made: handles that stay checkable, read-only views of
// cells, and the change hook a refiner installs to learn, inside each
// operation, which cells it created (and, on request, which it destroyed).
//
// Handles. Ids are recycled: a CellId or VertexId names whatever lives there
// now. A handle adds the incarnation, which is unique over the
// triangulation's whole life for that id, so a stale handle is detected
// (Triangulation::cell(h) returns nothing, Engine::visit reports the cell
// dead) and never read as the cell that replaced it. A vertex incarnation is
// unique in the whole process, so a VertexHandle of one triangulation reads
// as dead in any other (and after `t = Triangulation()`). A cell
// incarnation is counted per id and triangulation, so a CellHandle also names
// its triangulation's storage (CellHandle::mesh): it reads as dead in any
// other triangulation, and after `t = Triangulation()` or `t = std::move(u)`
// (where u's handles now name t's cells); clear() and shrink_to_fit() keep
// the counts going, so handles from before clear() read as dead, as do those
// of the cells shrink_to_fit() moved, also once their ids are reused.
//
// Keeping data per cell or vertex. Key it by id, and store the incarnation
// beside it: an entry whose incarnation differs from the handle's is stale.
// Ids stay below Triangulation::cell_id_bound() / vertex_id_bound(), which
// only grow until clear() (which resets them, and reports nothing: a refiner
// that keeps data per cell resets it with the triangulation; handles from
// before clear() read as dead), so a vector indexed by id (grown as needed)
// works. An id whose cell dies at incarnation 2^30 - 2 or later is retired
// for good rather than wrapping (one id per 2^30 reuses). Under an
// engine, give each entry an atomic incarnation written by the hook (which
// runs while the operation holds the cells) and read it before trusting the
// entry.
#include <array>
#include <cstdint>
#include <functional>
#include <span>

#include "pdt/geometry.hpp"

namespace pdt {

using VertexId = std::uint32_t;
using CellId = std::uint32_t;

inline constexpr VertexId infinite_vertex = 0;
inline constexpr VertexId no_vertex = 0xFFFFFFFFu;
inline constexpr CellId no_cell = 0xFFFFFFFFu;

// Which kind of operation a result or a change report is about.
enum class OpKind : std::uint8_t {
  insert,            // insert(p), insert_batch
  remove,            // remove(v)
  remove_insertion,  // Engine::remove_insertion(t), remove_insertions
  locate,            // Engine::locate(p)
  nearest_vertex,    // Engine::nearest_vertex(p)
  visit,             // Engine::visit(h, fn)
};

// A vertex incarnation: a removed vertex's id may be reused by a later
// insertion, with another incarnation.
struct VertexHandle {
  VertexId id = no_vertex;
  std::uint64_t incarnation = 0;  // 0: none
  friend bool operator==(const VertexHandle&, const VertexHandle&) = default;
};

// A cell incarnation. anchor is one of its finite vertices: holding it pins
// the cell's neighbourhood, which is how the engine reads a cell later. mesh
// numbers the storage the cell lives in: a number unique in the process (but
// for wrapping after 2^32 - 1 triangulations), given to each triangulation's
// storage when it is made (a Triangulation constructed, or the empty one
// that a moved-from object is left with), moved with it, kept by clear();
// never 0, so a default or hand-made handle without it reads as dead.
struct CellHandle {
  CellId id = no_cell;
  std::uint32_t incarnation = 0;
  VertexId anchor = no_vertex;
  std::uint32_t mesh = 0;
  friend bool operator==(const CellHandle&, const CellHandle&) = default;
};

// A tetrahedron as a refiner sees it: positively oriented; an infinite cell
// (outside the convex hull) has the infinite vertex (id 0) in one slot,
// whose point is left at (0, 0, 0).
struct CellView {
  CellHandle handle;
  std::array<VertexId, 4> vertices{};
  std::array<Point3, 4> points{};
  bool finite() const {
    return vertices[0] != infinite_vertex && vertices[1] != infinite_vertex && vertices[2] != infinite_vertex &&
           vertices[3] != infinite_vertex;
  }
};

// Reported once per operation that created or deleted a vertex (a duplicate
// insertion, or a removal that only lowers a multiplicity, changes no cell
// and is not reported). The spans are valid only during the call.
struct Changes {
  OpKind kind = OpKind::insert;    // insert, or remove (also for remove_insertion)
  VertexHandle vertex;             // the vertex inserted, or removed
  std::span<const CellView> created;       // every cell the operation made
  std::span<const CellHandle> destroyed;   // the cells it deleted, if asked for (else empty)
};

// Called inside the operation, while it still holds its cells: every created
// cell is as reported, and stays so until the hook returns. Under an engine it
// runs on a worker while other workers go on elsewhere, so keep it short and
// thread-safe; it may submit further operations (they run later), but must not
// wait for any. It may run and wait for TBB work of its own (a parallel_for
// over the cells), also in the engine's arena (engine.hpp). An exception it throws does not undo the operation: the
// engine keeps the first one and drain() rethrows it; the sequential
// Triangulation lets it propagate from insert/remove (the operation is done).
// A sequential triangulation's hook sees the change complete: its const
// queries (counts, cell(h), validate()) agree with the report. It may not
// change that triangulation (insert, remove, clear, set_change_hook, a move:
// pdt::Error), nor destroy it (the process stops, naming the rule). Under an
// engine, the triangulation's const queries are for quiescent times only
// (triangulation.hpp); from a hook, read cells through the report.
using ChangeHook = std::function<void(const Changes&)>;

}  // namespace pdt
