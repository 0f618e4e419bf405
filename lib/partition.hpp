#pragma once
// Partition (paper §3.1): the domain box cut into blocks_per_axis^3 blocks,
// numbered x fastest, and given to the workers in contiguous runs, so each
// worker owns a compact region. An operation goes to the worker owning its
// point's block.
#include "box_lattice.hpp"
#include "pdt/geometry.hpp"

namespace pdt::detail {

class Partition {
 public:
  Partition(const Box& domain, unsigned blocks_per_axis, unsigned workers)
      : lattice_(corner(domain.lo), corner(domain.hi), static_cast<int>(blocks_per_axis)),
        blocks_per_axis_(blocks_per_axis),
        workers_(workers) {}

  unsigned worker_of(const Point3& p) const {
    const std::size_t b = blocks_per_axis_;
    const std::size_t block = (static_cast<std::size_t>(lattice_.index(2, p.z)) * b + lattice_.index(1, p.y)) * b +
                              lattice_.index(0, p.x);
    return static_cast<unsigned>(block * workers_ / (b * b * b));
  }
  unsigned blocks_per_axis() const { return blocks_per_axis_; }

 private:
  struct Corner {
    double c[3];
    operator const double*() const { return c; }
  };
  static Corner corner(const Point3& p) { return {{p.x, p.y, p.z}}; }
  BoxLattice lattice_;
  unsigned blocks_per_axis_, workers_;
};

}  // namespace pdt::detail
