"""02 - Check a cell's taught poses: inside the limits, collision-free, clearance.

    .venv/bin/python examples/02_check_a_cell.py [scene folder]
"""

import sys

import safepath

cell = safepath.load_cell(sys.argv[1] if len(sys.argv) > 1 else "scenes/quality_check_cell")
for check in safepath.check_poses(cell):
    r = check.report
    state = "holding" if check.held else "empty"
    pair = " / ".join(r.closest_pair) if r.closest_pair else "-"
    print(f"{check.pose:<8} {state:<8} valid {r.valid!s:<5} clearance "
          f"{r.clearance * 1000:6.1f} mm ({pair})")
