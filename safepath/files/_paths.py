"""Where the bundled robot and scene folders are, in a checkout and in an installed wheel.

The folders live at the top of the repository (``robots/``, ``scenes/``), where they are
edited. ``safepath/_data/robots`` and ``safepath/_data/scenes`` are symbolic links to
them in a checkout; building a wheel copies the linked folders into the package (see
``[tool.setuptools.package-data]`` in ``pyproject.toml``), so the same paths hold the
data in a ``pip install``-ed library, from any working directory.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["ROBOTS_DIR", "SCENES_DIR"]

_DATA = Path(__file__).resolve().parents[1] / "_data"

#: The bundled robot folders (``robots/<name>/robot.yaml``); ``$SAFEPATH_ROBOTS`` overrides.
ROBOTS_DIR = Path(os.environ.get("SAFEPATH_ROBOTS", _DATA / "robots"))
#: The bundled scene folders (``scenes/<name>/scene.yaml``); ``$SAFEPATH_SCENES`` overrides.
SCENES_DIR = Path(os.environ.get("SAFEPATH_SCENES", _DATA / "scenes"))
