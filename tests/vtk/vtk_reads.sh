#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# The vtk.reads test: pdt writes .vtu files (binary zlib, ASCII, a refined
# mesh with cell fields) and VTK's own reader must read them back as the
# TetGen files of the same runs. Skipped (exit 77, with a message) when VTK's
# Python bindings are not installed.
#   vtk_reads.sh PDT_TOOL WORK_DIR
set -euo pipefail
pdt=$1
work=$2
here=$(cd "$(dirname "$0")" && pwd)
python=/usr/bin/python3
[ -x "$python" ] || python=python3
rm -rf "$work" && mkdir -p "$work" && cd "$work"
"$python" -c "import vtk" 2>/dev/null || exec "$python" "$here/check_vtu.py" none.node
"$pdt" gen --dist normal --points 3000 --remove-fraction 0.2 --interleaved --out s.ops > /dev/null
"$pdt" run s.ops --out m.node > /dev/null
"$pdt" run s.ops --out z.vtu > /dev/null
"$pdt" run s.ops --threads 3 --vtu-ascii --out a.vtu > /dev/null
"$pdt" refine --domain torus --size 0.15 --threads 2 --out r.vtu > /dev/null
exec "$python" "$here/check_vtu.py" m.node z.vtu a.vtu r.vtu:radius_edge_ratio,min_dihedral_angle,domain_label
