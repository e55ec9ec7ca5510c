"""No library module grows past 700 lines (issue 26): a module that long holds more than
one idea, and the layer it belongs to should split it by responsibility."""

from __future__ import annotations

from pathlib import Path

import safepath

LIMIT = 700


def test_no_library_module_is_over_700_lines() -> None:
    package = Path(safepath.__file__).resolve().parent
    sizes = {path.relative_to(package.parent).as_posix(): len(path.read_text().splitlines())
             for path in package.rglob("*.py")}
    assert len(sizes) > 100  # the walk found the package
    over = {name: n for name, n in sizes.items() if n > LIMIT}
    assert not over, f"modules over {LIMIT} lines: {over}"
