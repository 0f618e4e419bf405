// SPDX-License-Identifier: MIT
// Catch2 2.13 indents a wrapped test or section name, or message, after its ": "; when
// that falls near the console width (79 by default) a failure there prints hyphens
// without end (54 GB in ten minutes, with SIGTERM ignored). At a width of 200 no test
// or section name wraps (the longest is 111 characters), and a message would need its
// ": " near column 200.
#define CATCH_CONFIG_CONSOLE_WIDTH 200
#define CATCH_CONFIG_MAIN
#include <catch2/catch.hpp>
