"""One virtualenv per peer planner, created once and cached.

Each peer is installed from PyPI into its own venv under ``benchmarks/results/envs/<name>``
(gitignored), because their pins conflict with safepath's (mplib needs numpy < 2,
pyroboplan pins pin 4.0.0 and toppra 0.6.3). A successful install leaves
``envs/<name>/bench_env.json`` (requirements, install time [s], versions); a failed one
leaves ``envs/<name>.failed.json`` (the command, the exit status and the tail of pip's
output) and is retried on the next run. Nothing here raises on a failed install: the
status says what happened, and the benchmark reports it.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

__all__ = ["PeerSpec", "EnvStatus", "PEERS", "ENVS_DIR", "ensure_env", "closure_size",
           "import_seconds"]

REPO = Path(__file__).resolve().parents[2]
ENVS_DIR = REPO / "benchmarks" / "results" / "envs"
ADAPTERS = Path(__file__).resolve().parent / "adapters"


@dataclass(frozen=True)
class PeerSpec:
    """A peer planner and how to install it.

    Attributes:
        name: Short name (also the venv folder name).
        requirements: pip requirement strings, exact versions for reproducibility.
        distribution: Top-level distribution whose dependency closure is its size.
        imports: Modules the adapter imports (timed for the import-time figure).
        adapter: Adapter script in ``adapters/`` (runs inside the venv).
    """

    name: str
    requirements: tuple[str, ...]
    distribution: str
    imports: tuple[str, ...]
    adapter: str


PEERS: dict[str, PeerSpec] = {
    "mplib": PeerSpec("mplib", ("mplib==0.2.1", "numpy<2"), "mplib", ("mplib",),
                      "mplib_adapter.py"),
    "pyroboplan": PeerSpec("pyroboplan", ("pyroboplan==1.3.1",), "pyroboplan",
                           ("pyroboplan.planning.rrt", "pyroboplan.planning.path_shortcutting",
                            "pyroboplan.trajectory.trapezoidal_velocity"),
                           "pyroboplan_adapter.py"),
    "roboplan": PeerSpec("roboplan", ("roboplan==0.7.0",), "roboplan",
                         ("roboplan.core", "roboplan.rrt", "roboplan.toppra"),
                         "roboplan_adapter.py"),
}


@dataclass
class EnvStatus:
    """What happened when a peer's venv was requested.

    Attributes:
        name: Peer name.
        ok: Whether the venv exists and imports the peer.
        python: The venv's interpreter (None when not ok).
        cached: The venv was already there (install time is the recorded one).
        install_seconds: Wall time of ``pip install`` when the venv was created [s].
        error: Why it is not ok (pip's exit status and output tail, or import error).
        versions: Installed versions of the main distributions.
        site_packages_bytes: ``du`` of the venv's site-packages [bytes].
    """

    name: str
    ok: bool
    python: str | None = None
    cached: bool = False
    install_seconds: float | None = None
    error: str | None = None
    versions: dict[str, str] = field(default_factory=dict)
    site_packages_bytes: int | None = None

    def to_json(self) -> dict:
        """A JSON-ready dict."""
        return asdict(self)


def _venv_python(folder: Path) -> Path:
    return folder / "bin" / "python"


def _du(path: Path) -> int:
    total = 0
    for root, _, files in os.walk(path):
        for f in files:
            p = Path(root) / f
            if not p.is_symlink():
                total += p.stat().st_size
    return total


def _site_packages(python: Path) -> Path:
    out = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()"
                          "['purelib'])"], capture_output=True, text=True, check=True)
    return Path(out.stdout.strip())


_VERSIONS = """
import importlib.metadata as md, json, sys
out = {}
for name in sys.argv[1:]:
    try:
        out[name] = md.version(name)
    except md.PackageNotFoundError:
        pass
print(json.dumps(out))
"""


def _versions(python: Path, names: list[str]) -> dict[str, str]:
    out = subprocess.run([str(python), "-c", _VERSIONS, *names], capture_output=True,
                         text=True, timeout=120)
    return json.loads(out.stdout) if out.returncode == 0 else {}


def _check_imports(python: Path, spec: PeerSpec) -> str | None:
    code = "; ".join(f"import {m}" for m in spec.imports)
    out = subprocess.run([str(python), "-c", code], capture_output=True, text=True,
                         timeout=300)
    if out.returncode != 0:
        return "import failed: " + out.stderr.strip().splitlines()[-1][-500:] \
            if out.stderr.strip() else f"import failed (exit {out.returncode})"
    return None


def ensure_env(spec: PeerSpec, *, create: bool = True, timeout: float = 2400.0,
               log: bool = True) -> EnvStatus:
    """The peer's venv: reuse the cached one, else create it (if ``create``).

    Args:
        spec: The peer.
        create: Create the venv when it is missing (else report it missing).
        timeout: Limit on ``pip install`` [s].
        log: Print progress on stderr (this is a script, not the library).

    Returns:
        The status; ``ok`` False carries the reason in ``error``.
    """
    folder = ENVS_DIR / spec.name
    stamp = folder / "bench_env.json"
    failed = ENVS_DIR / f"{spec.name}.failed.json"
    python = _venv_python(folder)
    names = [spec.distribution, "numpy", "pin", "toppra"]
    if stamp.exists() and python.exists():
        record = json.loads(stamp.read_text())
        if record.get("requirements") == list(spec.requirements):
            error = _check_imports(python, spec)
            if error is None:
                return EnvStatus(spec.name, True, str(python), True,
                                 record.get("install_seconds"), None,
                                 record.get("versions", {}),
                                 _du(_site_packages(python)))
    if not create:
        return EnvStatus(spec.name, False, error="venv not created (run without --no-install)")
    if folder.exists():
        shutil.rmtree(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    if log:
        print(f"[envs] creating {folder} ({' '.join(spec.requirements)})", file=sys.stderr,
              flush=True)
    t0 = time.perf_counter()
    steps = [[sys.executable, "-m", "venv", str(folder)],
             # No pip cache: the recorded install time is a fresh machine's (downloads
             # and source builds included), whatever this machine installed before.
             [str(python), "-m", "pip", "install", "--disable-pip-version-check",
              "--no-input", "--quiet", "--no-cache-dir", *spec.requirements]]
    for cmd in steps:
        try:
            out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return _fail(spec, failed, cmd, f"timed out after {timeout:.0f} s",
                         time.perf_counter() - t0)
        if out.returncode != 0:
            tail = "\n".join(line for line in (out.stdout + out.stderr).splitlines()
                             if "is ignored: it is neither" not in line)[-2000:]
            return _fail(spec, failed, cmd, f"exit {out.returncode}: {tail}",
                         time.perf_counter() - t0)
    seconds = time.perf_counter() - t0
    error = _check_imports(python, spec)
    if error is not None:
        return _fail(spec, failed, ["import", *spec.imports], error, seconds)
    versions = _versions(python, names)
    stamp.write_text(json.dumps({"requirements": list(spec.requirements),
                                 "install_seconds": round(seconds, 1),
                                 "python": sys.version.split()[0],
                                 "created": time.strftime("%Y-%m-%d %H:%M:%S"),
                                 "versions": versions}, indent=2))
    failed.unlink(missing_ok=True)
    if log:
        print(f"[envs] {spec.name} installed in {seconds:.0f} s", file=sys.stderr, flush=True)
    return EnvStatus(spec.name, True, str(python), False, round(seconds, 1), None, versions,
                     _du(_site_packages(python)))


def _fail(spec: PeerSpec, failed: Path, cmd: list[str], error: str,
          seconds: float) -> EnvStatus:
    failed.write_text(json.dumps({"command": cmd, "error": error,
                                  "seconds": round(seconds, 1)}, indent=2))
    print(f"[envs] {spec.name} FAILED: {error.splitlines()[0][:200]}", file=sys.stderr,
          flush=True)
    return EnvStatus(spec.name, False, None, False, round(seconds, 1), error)


_CLOSURE = """
import importlib.metadata as md, json, re, sys
def norm(n):
    return re.sub(r"[-_.]+", "-", n).lower()
seen, todo, total = set(), [sys.argv[1]], 0
while todo:
    name = norm(todo.pop())
    if name in seen:
        continue
    seen.add(name)
    try:
        dist = md.distribution(name)
    except md.PackageNotFoundError:
        continue
    for f in dist.files or []:
        p = f.locate()
        try:
            total += p.stat().st_size
        except OSError:
            pass
    for req in dist.requires or []:
        if "extra ==" in req:
            continue
        todo.append(re.split(r"[ ;<>=!~\\[(]", req.strip(), maxsplit=1)[0])
print(json.dumps({"bytes": total, "distributions": sorted(seen)}))
"""


def closure_size(python: str | Path, distribution: str) -> dict:
    """Bytes of a distribution and its runtime dependencies, as installed.

    Runs inside ``python`` (a venv's interpreter) and sums the files each distribution
    lists in its RECORD, following ``Requires-Dist`` without extras.
    """
    out = subprocess.run([str(python), "-c", _CLOSURE, distribution], capture_output=True,
                         text=True, timeout=300, check=True)
    return json.loads(out.stdout)


def import_seconds(python: str | Path, modules: tuple[str, ...], *, repeats: int = 3
                   ) -> float:
    """Median wall time of a fresh ``python -c "import ..."`` [s] (interpreter start
    included; the bare interpreter start is measured separately by the caller)."""
    code = "; ".join(f"import {m}" for m in modules)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run([str(python), "-c", code], capture_output=True, check=True,
                       timeout=600)
        times.append(time.perf_counter() - t0)
    return sorted(times)[len(times) // 2]


if __name__ == "__main__":
    # `python benchmarks/peers/envs.py`: create (or check) every peer venv.
    for peer in PEERS.values():
        status = ensure_env(peer)
        print(json.dumps(status.to_json()))
