// SPDX-License-Identifier: MIT
#pragma once
// pdt: dynamic, parallel 3D Delaunay triangulation. Umbrella header.
#include "pdt/engine.hpp"
#include "pdt/error.hpp"
#include "pdt/generate.hpp"
#include "pdt/geometry.hpp"
#include "pdt/io.hpp"
#include "pdt/ops.hpp"
#include "pdt/triangulation.hpp"
