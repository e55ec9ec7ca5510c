"""The disk cache of what the sphere layer makes from a robot alone (``safepath.files.derived``,
its stored kind): an entry read back is the part made afresh, bit for bit; a damaged
entry is ignored with a warning and made again; other options or geometry are another
entry; ``SAFEPATH_CACHE=0`` writes nothing; ``load_cell`` makes (or reads) it, and what
the checkers and verifiers take from the robot, before the first plan."""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from safepath import CollisionChecker
from safepath.cell import Cell
from safepath.collision import CheckOptions, LayerOptions
from safepath.collision.layer import SphereLayer
from safepath.files.derived import CACHE_ENV, StoredKind, disk_folder, read_entry


def _stored(cell: Cell, options: LayerOptions) -> tuple[StoredKind[Any], Any]:
    """The robot's value kept on disk (the sphere layer's part) for ``options``: its kind
    and value."""
    (found,) = [(kind, value) for (kind, opts), value in cell.robot.derived.held().items()
                if isinstance(kind, StoredKind) and opts == options]
    return found


def _made(cell: Cell, options: LayerOptions) -> Any:
    """The sphere layer's part of the cell's robot, with nothing kept in memory: read from
    the disk or fitted afresh (by a layer of a checker that builds none itself)."""
    cell.robot.derived.forget()
    exact = CollisionChecker(cell.robot, cell.scene, options=CheckOptions(fast=False))
    SphereLayer(exact.layer_source(), options)
    return _stored(cell, options)[1]


def _arrays(cell: Cell, part: Any) -> dict[str, np.ndarray]:
    kind, _ = _stored(cell, LayerOptions())
    return kind.to_arrays(part)


def test_a_part_read_back_is_the_part_made(cell: Cell, tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    options = LayerOptions()
    made = _made(cell, options)
    entries = list((tmp_path / "robot-parts").glob("*.part"))
    assert len(entries) == 1
    fresh_layer = CollisionChecker(cell.robot, cell.scene).layer
    read = _made(cell, options)
    assert read is not made
    a, b = _arrays(cell, made), _arrays(cell, read)
    assert a.keys() == b.keys()
    for name in a:
        assert a[name].dtype == b[name].dtype and a[name].shape == b[name].shape, name
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    assert not read.movers[0].fit.outer_centers.flags.writeable  # shared, read-only
    # The layer's buffers from the part read back are those of the part made.
    read_layer = CollisionChecker(cell.robot, cell.scene).layer
    assert fresh_layer is not None and read_layer is not None
    np.testing.assert_array_equal(fresh_layer.F, read_layer.F)
    np.testing.assert_array_equal(fresh_layer.I, read_layer.I)


@pytest.mark.parametrize("damage", ["garbage", "truncated", "flipped"])
def test_a_damaged_entry_is_ignored_with_a_warning_and_made_again(
        cell: Cell, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture, damage: str) -> None:
    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    options = LayerOptions()
    made = _arrays(cell, _made(cell, options))
    (entry,) = (tmp_path / "robot-parts").glob("*.part")
    raw = entry.read_bytes()
    if damage == "garbage":
        entry.write_bytes(b"not a cache entry")
    elif damage == "truncated":
        entry.write_bytes(raw[: len(raw) // 2])
    else:  # one byte of an array changed: the digest tells
        entry.write_bytes(raw[:-9] + bytes([raw[-9] ^ 0x10]) + raw[-8:])
    with caplog.at_level(logging.WARNING, logger="safepath.files.derived"):
        again = _arrays(cell, _made(cell, options))
    assert any("ignored" in r.getMessage() and entry.name in r.getMessage()
               for r in caplog.records)
    for name in made:
        np.testing.assert_array_equal(made[name], again[name], err_msg=name)
    assert read_entry(entry.read_bytes()).keys() == made.keys()  # written anew


@pytest.mark.parametrize("plant", ["fifo", "link"])
def test_a_pipe_or_link_planted_as_an_entry_neither_hangs_nor_writes_through(
        cell: Cell, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, plant: str) -> None:
    """A named pipe at an entry's name is not opened (reading it would block for ever);
    a link there to another file is not written through: the entry is made again and
    replaces the link itself, the file it pointed to keeps its content."""
    import os

    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    options = LayerOptions()
    made = _arrays(cell, _made(cell, options))
    (entry,) = (tmp_path / "robot-parts").glob("*.part")
    entry.unlink()
    victim = tmp_path / "victim.txt"
    victim.write_text("mine\n")
    if plant == "fifo":
        os.mkfifo(entry)
    else:
        entry.symlink_to(victim)
    again = _arrays(cell, _made(cell, options))
    for name in made:
        np.testing.assert_array_equal(made[name], again[name], err_msg=name)
    assert victim.read_text() == "mine\n"
    assert entry.is_file() and not entry.is_symlink()  # the entry, written anew
    assert read_entry(entry.read_bytes()).keys() == made.keys()


def test_other_options_or_geometry_are_another_entry(cell: Cell, tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    folder = tmp_path / "robot-parts"
    _made(cell, LayerOptions())
    _made(cell, LayerOptions(cell=0.03))
    assert len(list(folder.glob("*.part"))) == 2
    geom = cell.robot.collision_model.geometryObjects[3]
    placement = geom.placement.copy()
    try:
        moved = placement.copy()
        moved.translation = placement.translation + np.array([0.0, 0.0, 0.01])
        geom.placement = moved
        part = _made(cell, LayerOptions())
        assert len(list(folder.glob("*.part"))) == 3
        np.testing.assert_allclose(part.movers[3].row[13:16] - placement.translation,
                                   [0.0, 0.0, 0.01], atol=1e-12)
    finally:
        geom.placement = placement
        cell.robot.derived.forget()


def test_no_disk_cache_when_turned_off(cell: Cell, tmp_path: Path,
                                       monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(CACHE_ENV, "0")
    assert disk_folder() is None
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    _made(cell, LayerOptions())
    assert not any(tmp_path.rglob("*.part"))


def test_load_cell_prepares_what_the_checkers_and_verifiers_take_from_the_robot() -> None:
    # A loaded cell's first plan pays for planning: the robot's links and reach, the
    # verifier's shapes and (with the kernels built) the sphere layer's part are made
    # by load_cell, and the cell's checkers and verifiers use those, not new ones.
    from safepath import _aot, load_cell
    from safepath.verify import FclVerifier

    cell = load_cell("quality_check_cell")
    made = cell.robot.derived.held()
    names = {kind.name for kind, _ in made}
    assert {"collision checker's links and reach", "release verifier's bodies"} <= names
    assert ("sphere layer robot part" in names) is (_aot.compiled() is not None)
    checker = CollisionChecker(cell.robot, cell.scene, held="vial")
    assert checker.layer is not None
    FclVerifier(cell.robot, cell.scene, held="vial")
    held = cell.robot.derived.held()
    assert all(held[key] is value for key, value in made.items())


def test_a_robot_the_verifier_cannot_check_loads_and_planning_refuses_it(cell: Cell) -> None:
    # Loading prepares the verifier's part only for a robot it can check (unverifiable
    # lists what it cannot, without raising); such a robot still loads (to be viewed and
    # edited), and check_verifiable, which planning runs first, refuses it by name.
    import copy

    import coal

    from safepath.cell import prepare_robot
    from safepath.errors import ConfigError
    from safepath.verify import check_verifiable, unverifiable

    assert unverifiable(cell.robot, cell.scene) == []
    odd = copy.copy(cell.robot)
    odd.collision_model = cell.robot.collision_model.copy()
    geom = odd.collision_model.geometryObjects[2]
    geom.geometry = coal.Ellipsoid(0.02, 0.03, 0.04)
    (refused,) = unverifiable(odd)
    assert refused.key == geom.name
    prepare_robot(odd)
    assert "release verifier's bodies" not in {kind.name for kind, _ in odd.derived.held()}
    with pytest.raises(ConfigError) as caught:
        check_verifiable(odd, cell.scene)
    assert caught.value.key == geom.name


def test_the_default_cache_belongs_to_the_virtual_environment(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # In a virtual environment the default cache is in it (any home directory finds what
    # it holds); outside one, or in one that cannot be written, the user's cache.
    import sys

    from safepath._aot import cache_root
    from safepath.files._home import cache_base

    monkeypatch.delenv(CACHE_ENV, raising=False)
    monkeypatch.delenv("SAFEPATH_KERNEL_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    venv = tmp_path / "venv"
    venv.mkdir()
    monkeypatch.setattr(sys, "prefix", str(venv))
    monkeypatch.setattr(sys, "base_prefix", str(tmp_path / "python"))
    assert cache_base() == venv / "var" / "cache" / "safepath"
    assert disk_folder() == venv / "var" / "cache" / "safepath" / "robot-parts"
    assert cache_root() == venv / "var" / "cache" / "safepath" / "kernels"
    venv.chmod(0o555)
    try:
        if not os.access(venv, os.W_OK):  # (root writes anywhere)
            assert cache_base() == tmp_path / "xdg" / "safepath"
    finally:
        venv.chmod(0o755)
    monkeypatch.setattr(sys, "base_prefix", str(venv))
    assert cache_base() == tmp_path / "xdg" / "safepath"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_base() == tmp_path / "home" / ".cache" / "safepath"
