"""Make ahead what a new process's first plan of a bundled cell would otherwise make.

``safepath build-kernels`` runs this module in a new process, one that loads the kernels
it has just built: loading each bundled cell writes its robot's sphere-layer part to the
disk cache (:mod:`safepath.files.derived`; made only where the kernels are compiled ahead
of time), and the classes of the messages a bag holds are generated once
(:mod:`safepath.ros._type_cache`). A user's own cell makes its part on its first load, as
before. Nothing here changes a plan: it only moves work out of the first one.
"""

from __future__ import annotations

__all__ = ["prepare"]


def prepare() -> list[str]:
    """Load every bundled cell and the written message classes; returns the cells' names."""
    from .. import load_cell
    from ..files._paths import SCENES_DIR
    from ..ros import messages

    names = []
    for folder in sorted(SCENES_DIR.iterdir()):
        if (folder / "scene.yaml").is_file():
            load_cell(folder)
            names.append(folder.name)
    messages.written_typestore()
    return names


if __name__ == "__main__":
    print(", ".join(prepare()))
