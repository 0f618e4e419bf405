// SPDX-License-Identifier: MIT
#pragma once
// AffineBasis: affinely independent vertices picked greedily from a sequence:
// the first vertex, the next one at another point, the next one off their
// line, the next one off their plane. dimension() is how many dimensions the
// sequence offered so far spans (-1 for none, up to 3). The lower-dimensional
// states, the removal's "does the set become flat?" test and validate() all
// use it, so they agree on what "coplanar" means.
#include <array>

#include "predicates.hpp"
#include "storage.hpp"

namespace pdt::detail {

class AffineBasis {
 public:
  // Offers vertex v at point p (which must outlive the basis); returns true
  // when it raised the dimension, i.e. v joined the basis.
  bool offer(VertexId v, const KPoint& p) {
    switch (size_) {
      case 0: break;
      case 1: if (p == *points_[0]) return false; break;
      case 2: if (CGAL::collinear(*points_[0], *points_[1], p)) return false; break;
      case 3: if (orient(*points_[0], *points_[1], *points_[2], p) == 0) return false; break;
      default: return false;
    }
    ids_[size_] = v;
    points_[size_++] = &p;
    return true;
  }
  // Would p raise the dimension (without offering it)?
  bool raises(const KPoint& p) const {
    AffineBasis probe = *this;
    return probe.offer(no_vertex, p);
  }
  int dimension() const { return size_ - 1; }
  VertexId operator[](int i) const { return ids_[i]; }
  bool contains(VertexId v) const {
    for (int i = 0; i < size_; ++i)
      if (ids_[i] == v) return true;
    return false;
  }
  void clear() { size_ = 0; }

 private:
  std::array<VertexId, 4> ids_{};
  std::array<const KPoint*, 4> points_{};
  int size_ = 0;
};

}  // namespace pdt::detail
