// SPDX-License-Identifier: MIT
#pragma once
// Whether pdt's large arrays (a triangulation's cells, cell tags and
// vertices; an engine's ticket slots) ask the kernel for transparent huge
// pages with madvise(MADV_HUGEPAGE).
//
// PDT_HUGE_PAGES=1 asks; 0 or unset does not, and the system's own policy
// (/sys/kernel/mm/transparent_hugepage/enabled) decides. Read once, at the
// first large array. Why off by default, measured (README, Design, Huge
// pages): huge pages save TLB misses on random access (1M points inserted
// one at a time in random order: 4% faster with them) but on a virtual
// machine a fresh huge page can cost the host's first touch (a batch of 1M
// points: 3.36 s with them, 2.93 s without, on the Intel VM of
// bench/results/*-intel.txt).
namespace pdt::detail {

// Throws pdt::Error (invalid_argument) naming the variable when it is set to
// anything but 0 or 1.
bool huge_pages_advised();

}  // namespace pdt::detail
