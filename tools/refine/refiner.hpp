// SPDX-License-Identifier: MIT
#pragma once
// A parallel Delaunay refiner on pdt's public API only: pdt::Engine carries
// out every change, the refiner decides. Its rules (in the spirit of the
// paper's HQR):
//   - a tetrahedron is bad if its circumcentre lies inside the domain and its
//     circumradius exceeds `size` or its radius-edge ratio exceeds `ratio`;
//     a bad tetrahedron gets its circumcentre inserted;
//   - the domain's surface is protected by samples (domain.hpp), spaced about
//     `size` apart, each with a snap radius (snap_radius: a quarter of the
//     spacing) and a protecting radius (protect_radius: three quarters of
//     it). A circumcentre within a sample's snap radius is never inserted:
//     the sample is, instead, if it is not in yet (then the cell is judged
//     again); otherwise the cell is left, in the protected layer along the
//     surface. A circumsphere that holds a sample not in yet gets that sample
//     instead of its circumcentre. When the interior asks for nothing more,
//     the samples not inserted yet all go in, and refinement resumes. When a
//     sample is inserted, the vertices (not samples) inside its protecting
//     ball are removed. So the stream mixes insertions and removals, as the
//     paper's §4.2 trace does. The bounds hold for every tetrahedron whose
//     circumcentre is inside the domain and outside the protected layer;
//   - it terminates: the size bound and ratio >= 2 (Shewchuk's bound) keep
//     insertion radii from shrinking, and a point budget stops it anyway (and
//     is reported when hit).
// How it runs: the engine's change hook (on the workers, inside each
// operation) judges every cell an operation creates, queues the bad ones and
// notes every cell's incarnation (created and destroyed cells are reported),
// so a queued cell that has died since is recognised and skipped. Refiner
// coroutines, on the engine's arena, take cells from the queue and co_await
// the insertions; the hook submits the removals. Nothing else touches the
// triangulation.
#include <cstdint>
#include <functional>
#include <string>

#include "pdt/pdt.hpp"
#include "refine/domain.hpp"

namespace pdt_refine {

struct RefineOptions {
  Domain domain;
  double size = 0.1;        // the circumradius bound
  double ratio = 2;         // the radius-edge bound (at least min_ratio)
  unsigned workers = 1;     // the engine's workers (and the arena's threads, at most the cores)
  std::uint64_t seed = 1;   // which surface samples are kept
  std::uint64_t budget = 20000000;  // most points inserted
  // Where the operations carried out are written (null: nowhere). refine()
  // writes them but does not close the writer: the caller does (which puts
  // the file in place) once its other outputs are written too, so a run that
  // fails or is interrupted before then leaves an older file as it was.
  pdt::OpWriter* trace = nullptr;
  // Called now and then (from the calling thread) while it runs.
  std::function<void(std::uint64_t vertices, std::uint64_t queued, double seconds)> progress;
};

inline constexpr double min_ratio = 2;
inline double snap_radius(double size) { return 0.25 * size; }
inline double protect_radius(double size) { return 0.75 * size; }

struct RefineStats {
  std::uint64_t insertions = 0;   // circumcentres + samples + the box's corners
  std::uint64_t circumcentres = 0, samples = 0, removals = 0;
  std::uint64_t dead_skipped = 0;  // queued cells found dead when their turn came
  // Cells alive when their insertion was submitted and dead when it ran (an
  // engine operation that did nothing: insert_if_alive)
  std::uint64_t died_in_engine = 0;
  std::uint64_t protected_skipped = 0;  // bad cells left in the protected layer
  std::uint64_t surface_samples = 0;  // samples available
  std::uint64_t start_points = 0;     // the box's corners and the starting lattice
  bool budget_hit = false;
  // When the budget stopped it before a step of several points (the starting
  // lattice, or the surface samples still to go in, each all at once) rather
  // than at the budget itself: that step's points, which would have passed
  // it; else 0.
  std::uint64_t budget_step = 0;
  // The surface's samples alone exceed the budget: nothing was refined
  // (surface_samples: their number, or 0 when the sampling stopped early).
  bool samples_over_budget = false;
  double seconds = 0;
  pdt::EngineStats engine;
  unsigned workers = 0;
};

// Refines the empty triangulation t over o.domain. Throws pdt::Error
// (invalid_argument) for size <= 0, a ratio below min_ratio, no workers.
RefineStats refine(pdt::Triangulation& t, const RefineOptions& o);

// What a refined mesh looks like, judged independently of the refiner.
struct MeshQuality {
  std::uint64_t inside = 0;        // tetrahedra whose centroid is inside the domain
  std::uint64_t judged = 0;        // tetrahedra whose circumcentre is inside and not in the protected layer
  std::uint64_t protected_layer = 0;  // tetrahedra whose circumcentre is inside, in a sample's snap radius
  std::uint64_t violations = 0;    // of the judged, how many miss a bound
  // Tetrahedra inside (centroid) whose circumcentre doubles cannot place
  // (flat or nearly so: TetShape::ok); neither judged nor refined.
  std::uint64_t unplaced = 0;
  double worst_ratio = 0;          // largest radius-edge ratio among the judged
  double largest_radius = 0;       // largest circumradius among the judged
  double min_dihedral = 180;       // smallest dihedral angle among the inside, degrees
  double min_dihedral_judged = 180;  // the same among the judged
  // Inside tetrahedra with a dihedral angle under sliver_degrees: the
  // radius-edge bound does not exclude such slivers (flat tetrahedra whose
  // four vertices lie near a circle of their circumsphere).
  static constexpr double sliver_degrees = 5;
  std::uint64_t slivers = 0, slivers_judged = 0;
};
// The samples are those refine() used (the same size and seed). threads > 1
// judges the cells on that many threads, at most one per core (the same
// result).
MeshQuality measure(const pdt::Triangulation& t, const Domain& d, double size, double ratio, std::uint64_t seed,
                    unsigned threads = 1);

}  // namespace pdt_refine
