"""The kernels compiled ahead of time (safepath._aot): same answers as numba's JIT, the
signature table agrees with numba, a stale build is never used, and a process that
plans with a current build never imports numba.

The build itself is what ``make setup`` / ``safepath build-kernels`` writes to the
cache (the virtual environment's); the ``built`` fixture makes it if it is missing (about a minute).
"""

from __future__ import annotations

import copy
import json
import logging
import os
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import safepath
from safepath import _aot
from safepath._aot import guard
from safepath._aot.build import Build, build, python_function, signature
from safepath._aot.table import ENTRIES, MODULES, Entry

ROOT = Path(__file__).resolve().parents[1]
CELL = ROOT / "scenes" / "quality_check_cell"
PANDA = ROOT / "examples" / "cells" / "panda_cell"
#: Recorded calls kept per kernel (the first ones of the plans).
KEEP = 150


@pytest.fixture(scope="module")
def built() -> Build:
    return build()


def _jit(entry: Entry) -> Callable[..., Any]:
    """numba's JIT kernel of an entry (the one a process without the build runs)."""
    import numba
    from numba.core.registry import CPUDispatcher

    _aot.materialize()  # callees bound as numba dispatchers, whatever the mode
    value = getattr(sys.modules[entry.module], entry.function)
    if isinstance(value, CPUDispatcher):
        return value  # type: ignore[no-any-return]
    return numba.njit(cache=True, nogil=True)(python_function(entry))  # type: ignore[no-any-return]


def _same(a: Any, b: Any) -> bool:
    """Equal bit for bit (arrays: dtype, shape and bytes; tuples item by item)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.dtype == b.dtype
                and a.shape == b.shape and a.tobytes() == b.tobytes())
    if isinstance(a, tuple):
        return (isinstance(b, tuple) and len(a) == len(b)
                and all(_same(x, y) for x, y in zip(a, b, strict=True)))
    if isinstance(a, float):
        return np.float64(a).tobytes() == np.float64(b).tobytes()
    return bool(a == b) and type(a) is type(b)


def test_every_kernel_module_is_hashed_and_every_entry_exists() -> None:
    import importlib

    from safepath.timing import _topp

    for name in MODULES:
        importlib.import_module(name)
    _topp.compiled_kernels()
    assert {module for module, _ in _aot.decorated} <= set(MODULES)
    for name, entry in ENTRIES.items():
        assert entry.module in MODULES, name
        assert callable(python_function(entry)), name


def test_table_signatures_are_the_ones_numba_infers() -> None:
    """Compiling each entry with numba from the table's argument types gives the table's
    result type: a kernel whose arguments or result changed fails here."""
    from numba.core import sigutils, types

    for name, entry in ENTRIES.items():
        args, result = sigutils.normalize_signature(signature(entry))
        dispatcher = _jit(entry)
        dispatcher.compile(args)
        inferred = dispatcher.overloads[tuple(args)].signature.return_type
        if isinstance(inferred, types.BaseTuple):  # a constant item (march's True) is typed
            inferred = types.Tuple([types.unliteral(t) for t in inferred])  # as a literal
        assert inferred == result, f"{name}: numba infers {inferred}, the table says {result}"


@pytest.fixture(scope="module")
def recorded() -> dict[str, list[tuple[Any, ...]]]:
    """Arguments of real kernel calls: the bundled cell and the Panda cell planned (the
    first KEEP calls of every kernel, copied before the call: kernels write into some)."""
    from safepath.collision import _bounds
    from safepath.collision import _kernels as _fastkernels
    from safepath.kinematics import _ik_kernel
    from safepath.model import _fk_kernel, _joinkernel
    from safepath.monitor import _kernels as _monitor_kernels
    from safepath.timing import _topp
    from safepath.verify import _kernel as _verify_kernel

    calls: dict[str, list[tuple[Any, ...]]] = {name: [] for name in ENTRIES}
    by_function = {(e.module, e.function): n for n, e in ENTRIES.items()}

    def recorder(name: str, kernel: Callable[..., Any]) -> Callable[..., Any]:
        def call(*args: Any) -> Any:
            if len(calls[name]) < KEEP:
                calls[name].append(copy.deepcopy(args))
            return kernel(*args)
        return call

    patched: list[tuple[Any, str, Any]] = []
    for module in (_fastkernels, _bounds, _verify_kernel, _ik_kernel, _monitor_kernels,
                   _fk_kernel):
        for (mod, function), name in by_function.items():
            if mod == module.__name__:
                patched.append((module, function, getattr(module, function)))
                setattr(module, function, recorder(name, getattr(module, function)))
    kernels = _topp.compiled_kernels()
    saved = dict(kernels)
    kernels["backward"] = recorder("topp_backward", saved["backward"])
    kernels["forward"] = recorder("topp_forward", saved["forward"])
    kernels["tridiagonal"] = recorder("topp_tridiagonal", saved["tridiagonal"])
    kernels["knots"] = recorder("topp_knots", saved["knots"])
    kernels["jerk_shift"] = recorder("topp_jerk_shift", saved["jerk_shift"])
    kernels["jerk_rows"] = recorder("topp_jerk_rows", saved["jerk_rows"])
    kernels["fill_grid"] = recorder("topp_fill_grid", saved["fill_grid"])
    kernels["tighten"] = recorder("topp_tighten", saved["tighten"])
    kernels["jet"] = recorder("topp_jet", saved["jet"])
    kernels["evaluate"] = recorder("topp_evaluate", saved["evaluate"])
    kernels["grid_peaks"] = recorder("topp_grid_peaks", saved["grid_peaks"])
    kernels["acceleration_rows"] = recorder("topp_acceleration_rows",
                                            saved["acceleration_rows"])
    join = _joinkernel.compiled_kernels()
    saved_join = dict(join)
    join["peaks"] = recorder("join_peaks", saved_join["peaks"])
    join["sample"] = recorder("join_sample", saved_join["sample"])
    join["ratios"] = recorder("join_ratios", saved_join["ratios"])
    join["screen"] = recorder("join_screen", saved_join["screen"])
    try:
        for folder in (CELL, PANDA):
            cell = safepath.load_cell(folder)
            safepath.plan_cell(cell)
            _helpers(cell)
        _monitor(cell := safepath.load_cell(CELL), safepath.plan_cell(cell)["phase1"])
    finally:
        for module, function, value in patched:
            setattr(module, function, value)
        kernels.update(saved)
        join.update(saved_join)
    return calls


def _helpers(cell: safepath.Cell) -> None:
    """The kernels planning does not call but the API and the tests do, on real data."""
    from safepath.collision import _kernels as _fastkernels
    from safepath.kinematics import _ik_kernel
    from safepath.planning.cartesian import line_chain

    robot = cell.robot
    rng = np.random.default_rng(7)
    Q = rng.uniform(robot.lower, robot.upper, (200, robot.dof))
    checker = cell.checker(held=False)
    layer = checker.layer
    assert layer is not None
    _fastkernels.classify_many(Q, layer.F, layer.I, np.empty(len(Q), dtype=np.int64))
    for q in Q[:20]:
        checker.check(q)  # the sphere layer's pair bounds
    # The release check's placement of states off its grid (the check between samples,
    # which the bundled plans do not need).
    from safepath.verify import FclVerifier

    verifier = FclVerifier(robot, cell.scene)
    for m in range(len(verifier.movers)):
        verifier.poses_at(Q[:20], m)
    chain = line_chain(robot)
    args = (chain.joint_f, chain.joint_i, chain.frame_f)
    for q in Q[:20]:
        R, p, J = np.empty((3, 3)), np.empty(3), np.empty((6, robot.dof))
        _ik_kernel.tcp_pose(*args, q, R, p)
        _ik_kernel.tcp_jacobian(*args, q, J)
        _ik_kernel.log6(R, p, np.empty(6))
        _ik_kernel.jlog6(R, p, np.empty((6, 6)))
        q0 = np.clip(q + 0.05, robot.lower, robot.upper)
        _ik_kernel.solve(*args, R, p, q0, robot.lower.astype(float), robot.upper.astype(float),
                         np.array([1e-5, 1e-4, 0.1, 1e-6]), 50)


def _monitor(cell: safepath.Cell, phase1: safepath.Trajectory) -> None:
    """The monitor following phase 1: the table (the scene filter), points near the TCP
    (a slow-down, a stop: braking profiles), the arm's own (the self filter)."""
    from safepath.monitor import Cloud, Monitor, MonitorOptions
    from safepath.ros import split_at_gripper_events

    camera = np.eye(4)
    camera[:3, 3] = [1.2, 0.3, 0.4]
    motion = [m for m in split_at_gripper_events(phase1) if isinstance(m, safepath.Trajectory)][0]
    monitor = Monitor(cell, MonitorOptions(sensors={"cam": camera}, stale_after=0.06,
                                           self_filter=0.02))
    monitor.follow(motion, start=0.0, held="vial")
    rng = np.random.default_rng(1)
    table = np.column_stack([rng.uniform(0.0, 0.8, 100), rng.uniform(-0.2, 0.8, 100),
                             np.zeros(100)])
    tcp = cell.robot.tcp_position(motion.sample([0.55])[0][0])
    for stamp, points in ((0.0, table), (0.03, tcp[None, :] + [0.3, 0.0, 0.0]),
                          (0.55, tcp[None, :] + [[0.12, 0.0, 0.0], [0.0, 0.0, 0.02]])):
        monitor.observe(Cloud(stamp, "cam", points - camera[:3, 3]), stamp)


def test_ahead_of_time_kernels_answer_as_numba_bit_for_bit(
        built: Build, recorded: dict[str, list[tuple[Any, ...]]]) -> None:
    module, reason = _aot.load(built.path)
    assert module is not None, reason
    uncalled = {"verify_axis_bound", "verify_gjk_bound"}  # bound_between: diagnostics
    empty = sorted(n for n in set(ENTRIES) - uncalled if not recorded[n])
    assert not empty, f"no call recorded of {empty}"
    compared = 0
    for name, calls in recorded.items():
        entry = ENTRIES[name]

        def refuse(export: str, args: tuple[Any, ...]) -> Any:
            raise AssertionError(f"{export}: {guard.describe(args)} is not its signature")

        aot = guard.wrap(name, entry, getattr(module, name), refuse)
        jit = _jit(entry)
        for args in calls:
            a, b = copy.deepcopy(args), copy.deepcopy(args)
            out_a, out_b = aot(*a), jit(*b)
            assert _same(out_a, out_b), f"{name}: results differ"
            assert _same(a, b), f"{name}: arrays written differ"
            compared += 1
    assert compared >= 500


def test_arguments_off_the_signature_run_the_jit_kernel_or_raise_when_strict(
        built: Build, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """An int64 array where float64 is expected, or a strided view, would be read as the
    signature says by the raw extension: the guard hands such calls to numba instead."""
    module, _ = _aot.load(built.path)
    assert module is not None
    entry = ENTRIES["ik_log6"]
    taken: list[tuple[Any, ...]] = []

    def fallback(name: str, args: tuple[Any, ...]) -> Any:
        taken.append(args)
        return _aot.fallback(name, args)

    log6 = guard.wrap("ik_log6", entry, module.ik_log6, fallback)
    R = np.eye(3)
    p = np.array([0.1, -0.2, 0.3])
    out = np.empty(6)
    log6(R, p, out)
    assert not taken and np.allclose(out, [0.1, -0.2, 0.3, 0.0, 0.0, 0.0])
    strided = np.zeros(12)[::2]
    with pytest.raises(TypeError, match="do not match its signature"):
        log6(R, p, strided)  # the suite runs strict (tests/conftest.py)
    monkeypatch.setenv("SAFEPATH_AOT_STRICT", "0")
    expected = out.copy()
    with caplog.at_level(logging.WARNING, logger="safepath._aot"):
        log6(R, p, strided)
        np.testing.assert_array_equal(strided, expected)  # numba wrote through the view
        log6(R, p.astype(np.float32), out)
        np.testing.assert_allclose(out, expected, rtol=1e-6)
    assert len(taken) == 3
    assert "running numba's JIT kernel instead" in caplog.text


def test_a_build_of_other_sources_is_never_used(built: Build, tmp_path: Path) -> None:
    """Editing a kernel module (here _gjk.py, which only the sphere layer compiles) changes
    the key: the build is not found, whatever is in the cache."""
    copy_root = tmp_path / "safepath"
    shutil.copytree(_aot.PACKAGE, copy_root,
                    ignore=shutil.ignore_patterns("__pycache__", "*.so"))
    assert _aot.source_key(copy_root) == built.key
    assert _aot.find(copy_root)[0] == built.path
    with open(copy_root / "collision" / "_gjk.py", "a") as f:
        f.write("\n# edited after the build\n")
    stale_key = _aot.source_key(copy_root)
    assert stale_key != built.key
    path, reason = _aot.find(copy_root)
    assert path is None and "no build for these sources" in reason
    # The old build copied under the new key: its record names other sources.
    shutil.copytree(built.path.parent, _aot.build_dir(stale_key))
    try:
        path, reason = _aot.find(copy_root)
        assert path is None and "other sources" in reason
    finally:
        shutil.rmtree(_aot.build_dir(stale_key))


def _child(code: str, **env: str) -> list[str]:
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, timeout=600, env={**os.environ, **env})
    assert out.returncode == 0, out.stderr[-3000:]
    return out.stdout.split("\n")


_PLAN = ("import sys, safepath\n"
         "from safepath import _aot\n"
         f"trajectories = safepath.plan_cell(safepath.load_cell({str(CELL)!r}))\n"
         "print(_aot.status())\n"
         "print('numba' in sys.modules, 'llvmlite' in sys.modules)\n"
         "print(sorted(trajectories))\n")


def test_a_new_process_plans_the_cell_without_numba(built: Build) -> None:
    status, modules, routes = _child(_PLAN)[:3]
    assert status == f"ahead-of-time ({built.path})"
    assert modules == "False False"
    assert routes == str(sorted(safepath.load_cell(CELL).route_table()))


@pytest.mark.skipif(sys.prefix == sys.base_prefix, reason="not run in a virtual environment")
def test_the_build_is_found_under_any_home_directory(built: Build, tmp_path: Path) -> None:
    # In a virtual environment the build is kept in it: a process under an empty home
    # directory (no ~/.cache) still plans on it, never importing numba.
    env = {k: v for k, v in os.environ.items() if k not in ("SAFEPATH_KERNEL_CACHE",
                                                            "XDG_CACHE_HOME")}
    env["HOME"] = str(tmp_path)
    out = subprocess.run([sys.executable, "-c", _PLAN], cwd=ROOT, capture_output=True,
                         text=True, timeout=600, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    status, modules = out.stdout.split("\n")[:2]
    assert built.path.is_relative_to(Path(sys.prefix))
    assert status == f"ahead-of-time ({built.path})" and modules == "False False"
    assert not any(tmp_path.iterdir())


def test_without_a_build_the_kernels_run_on_numba(tmp_path: Path) -> None:
    status, modules, _ = _child(_PLAN, SAFEPATH_KERNEL_CACHE=str(tmp_path))[:3]
    assert status.startswith("numba JIT (no build for these sources in")
    assert modules == "True True"


@pytest.fixture()
def isolated_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    monkeypatch.setenv("SAFEPATH_KERNEL_CACHE", str(tmp_path))
    yield tmp_path


def test_an_unreadable_build_record_is_reported(built: Build, isolated_cache: Path) -> None:
    folder = _aot.build_dir(built.key)
    folder.mkdir(parents=True)
    (folder / _aot.META).write_text("{not json")
    path, reason = _aot.find()
    assert path is None and "unreadable build record" in reason
    (folder / _aot.META).write_text(json.dumps({"key": built.key, "file": "x.so",
                                                "exports": sorted(ENTRIES)}))
    path, reason = _aot.find()
    assert path is None and "lacks its extension x.so" in reason


def test_a_compiled_kernel_releases_the_gil(built: Build) -> None:
    """As numba's nogil=True kernels do: Python runs in another thread meanwhile (with
    the GIL held, this thread would run only around the call, a switch interval or so)."""
    import threading
    import time

    module, _ = _aot.load(built.path)
    assert module is not None
    cell = safepath.load_cell(CELL)
    layer = cell.checker(held=False).layer
    assert layer is not None
    Q = np.random.default_rng(0).uniform(cell.robot.lower, cell.robot.upper,
                                         (100_000, cell.robot.dof))
    out = np.empty(len(Q), dtype=np.int64)
    started, done = threading.Event(), threading.Event()
    call: list[float] = []

    def work() -> None:
        started.set()
        t0 = time.perf_counter()
        module.fast_classify_many(Q, layer.F, layer.I, out)
        call.append(time.perf_counter() - t0)
        done.set()

    thread = threading.Thread(target=work)
    thread.start()
    first = last = None
    while not done.is_set():
        if started.is_set():
            last = time.perf_counter()
            first = first or last
    thread.join()
    assert call[0] > 0.05 and first is not None and last is not None
    assert last - first > 0.5 * call[0], (last - first, call[0])


def test_build_kernels_command(built: Build, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                               capsys: pytest.CaptureFixture[str]) -> None:
    """Up to date: says where the build is. A cache it cannot write: one line, exit 2,
    nothing written."""
    from safepath.cli import main
    from safepath.files._paths import SCENES_DIR
    from safepath.files.derived import disk_folder

    monkeypatch.setenv("SAFEPATH_CACHE", str(tmp_path / "cache"))
    assert main(["build-kernels"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert out[0] == f"kernels up to date: {built.path}"
    # ... and the bundled cells' first plans are prepared: their robots' parts and the
    # bag's message classes are on disk (made by a new process, the build loaded).
    cells = sorted(f.name for f in SCENES_DIR.iterdir() if (f / "scene.yaml").is_file())
    assert out[1] == f"prepared the bundled cells' first plans: {', '.join(cells)}"
    parts = disk_folder()
    assert parts is not None and len(list(parts.glob("*.part"))) == len(cells)
    assert len(list((tmp_path / "cache" / "ros-types").glob("*.py"))) == 1
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv("SAFEPATH_KERNEL_CACHE", str(blocker / "kernels"))
    assert main(["build-kernels"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(
        f"safepath build-kernels: error: cannot write the kernel build to {blocker}")
    assert blocker.read_text() == ""


def test_the_cache_keeps_the_latest_builds(tmp_path: Path) -> None:
    import time

    from safepath._aot.build import prune

    folders = []
    for i in range(5):
        folder = tmp_path / f"build{i}"
        folder.mkdir()
        (folder / _aot.META).write_text("{}")
        os.utime(folder / _aot.META, (1000.0 + i, 1000.0 + i))
        folders.append(folder)
    (tmp_path / "not-a-build").mkdir()
    crashed = tmp_path / ".build-x"
    crashed.mkdir()
    os.utime(crashed, (time.time() - 7200, time.time() - 7200))
    running = tmp_path / ".build-y"
    running.mkdir()
    gone = prune(tmp_path, keep=3, current=folders[0])
    assert sorted(gone) == sorted([folders[1], folders[2], crashed])
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        ".build-y", "build0", "build3", "build4", "not-a-build"]


def test_guards_compiled_code_is_kept_next_to_the_build_and_a_bad_file_is_replaced(
        built: Build, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    """A new process finds the guards compiled (no compile call); a damaged file is
    ignored with a warning, the guards compiled again and the file made whole."""
    module, _ = _aot.load(built.path)
    assert module is not None
    monkeypatch.setattr(guard, "_codes", {})
    monkeypatch.setattr(guard, "_code_file", [])
    guard.keep_code_in(tmp_path)
    names = sorted(ENTRIES)[:3]
    first = [guard.wrap(n, ENTRIES[n], getattr(module, n), _aot.fallback) for n in names]
    kept = tmp_path / f"guards.{sys.implementation.cache_tag}.marshal"
    assert kept.is_file() and not list(tmp_path.glob("*.part"))

    def compiled_in_a_new_process() -> int:
        monkeypatch.setattr(guard, "_codes", {})  # a new process holds no code yet
        guard.keep_code_in(tmp_path)
        calls = []
        real = compile
        monkeypatch.setattr(guard, "compile", lambda *a: calls.append(a) or real(*a),
                            raising=False)
        again = [guard.wrap(n, ENTRIES[n], getattr(module, n), _aot.fallback)
                 for n in names]
        monkeypatch.delattr(guard, "compile")
        assert [f.__code__.co_code for f in again] == [f.__code__.co_code for f in first]
        return len(calls)

    assert compiled_in_a_new_process() == 0
    kept.write_bytes(b"\x00damaged")
    with caplog.at_level(logging.WARNING, logger="safepath._aot"):
        assert compiled_in_a_new_process() == len(names)
    assert "ignored" in caplog.text
    assert compiled_in_a_new_process() == 0
