"""One home per public name (issue 37): ``safepath.__all__`` is the short list a user
needs, and every public package's face exports only what that package defines: no name is
exported by two packages, and no package re-exports a neighbour's name (``LineOptions``
was exported three ways)."""

from __future__ import annotations

import importlib
import pkgutil
from collections import defaultdict
from types import ModuleType

import safepath


def _public_packages() -> list[ModuleType]:
    """Every package of safepath whose dotted name has no private part."""
    found = []
    for info in pkgutil.walk_packages(safepath.__path__, "safepath."):
        if info.ispkg and not any(p.startswith("_") for p in info.name.split(".")):
            found.append(importlib.import_module(info.name))
    return found


def _owner(obj: object) -> str | None:
    """The safepath module that defines ``obj`` (None for a constant or a type alias of
    builtins, which cannot say)."""
    module = getattr(obj, "__module__", None)
    ours = isinstance(module, str) and module.startswith("safepath.")
    return module if ours and callable(obj) else None


def misplaced(packages: list[ModuleType]) -> list[str]:
    """Names a package exports that another package defines, and names two export."""
    problems = []
    exporters: dict[str, list[str]] = defaultdict(list)
    for package in packages:
        for name in getattr(package, "__all__", ()):
            exporters[name].append(package.__name__)
            owner = _owner(getattr(package, name))
            if owner is not None and not owner.startswith(package.__name__ + "."):
                problems.append(f"{package.__name__} exports {name}, defined in {owner}")
    problems += [f"{name} is exported by {', '.join(where)}"
                 for name, where in sorted(exporters.items()) if len(where) > 1]
    return problems


def test_each_public_name_has_one_home() -> None:
    packages = _public_packages()
    assert {p.__name__ for p in packages} >= {
        "safepath.cell", "safepath.collision", "safepath.planning", "safepath.timing",
        "safepath.verify", "safepath.kinematics", "safepath.monitor", "safepath.model"}
    assert misplaced(packages) == []


def test_the_check_finds_a_name_exported_twice() -> None:
    """The check itself: a face re-exporting its neighbour's class is found, and so is a
    name two packages export."""
    here = ModuleType("safepath.here")
    there = ModuleType("safepath.there")

    class Options:
        pass

    Options.__module__ = "safepath.there.options"
    here.Options = there.Options = Options  # type: ignore[attr-defined]
    here.__all__ = there.__all__ = ["Options"]  # type: ignore[attr-defined]
    assert misplaced([here, there]) == [
        "safepath.here exports Options, defined in safepath.there.options",
        "Options is exported by safepath.here, safepath.there"]


def test_the_root_lists_what_a_user_needs_each_name_once() -> None:
    names = safepath.__all__
    assert len(names) == len(set(names))
    for name in names:
        assert getattr(safepath, name) is not None
    assert {"load_robot", "load_cell", "plan", "plan_cell", "Trajectory",
            "SafepathError"} <= set(names)
