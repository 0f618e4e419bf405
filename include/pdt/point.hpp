// SPDX-License-Identifier: MIT
#pragma once
// Kept for code written against pdt 0.1: Point3 (and Box) now live in geometry.hpp.
#include "pdt/geometry.hpp"
