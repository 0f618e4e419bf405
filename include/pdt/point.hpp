// SPDX-License-Identifier: MIT
#pragma once
// Kept for code that includes it: Point3 (and Box) live in geometry.hpp.
#include "pdt/geometry.hpp"
