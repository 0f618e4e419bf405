// SPDX-License-Identifier: MIT
#pragma once
// Internal: the point-file readers behind pdt::read_points, and the TetGen
// node reader that read_tetgen shares.
#include <cstdint>
#include <string>
#include <vector>

#include "io_util.hpp"
#include "pdt/geometry.hpp"

namespace pdt::detail {

// TetGen node list from the current position of f: a header "N dim nattr nbm"
// (dim must be 3), then N lines "index x y z [attributes] [marker]" with
// consecutive indices from the first one (0 or 1, returned in first_index).
std::vector<Point3> read_node_section(InputFile& f, std::uint64_t* first_index);
// At the end of a file whose header counts its lines (a .node, a .ele):
// bad_format at the first line with content left, naming the count (`what`:
// "the 12 nodes the header announces"). Blank and comment lines may follow.
void require_end(InputFile& f, const std::string& what);

}  // namespace pdt::detail
