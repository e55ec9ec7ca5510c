"""The sweep's results file: one JSON line per finished seed, appended as each finishes.

``results.jsonl`` starts with a header line (what the task is: its identity), then
one line per seed, ``{"seed": 7, "result": {...}, "time": 0.52}``, in the order the seeds
finished. Each line is written whole with one ``write`` and flushed to disk before the
next, so a kill leaves at most one half-written last line: opening the file again drops
it (the file is cut back to its last complete line) and its seed runs again. A line in
the middle that is no JSON, a seed twice, or a header of another task is no crash's
trace: it is refused, naming the file and the line. One sweep writes a file at a time
(an exclusive lock while it is open).
"""

from __future__ import annotations

import fcntl
import json
import os
from pathlib import Path
from typing import IO, Any

from ..errors import InputError
from .task import TaskResult

__all__ = ["ResultStore", "FORMAT"]

#: The header's format tag.
FORMAT = "safepath-sweep/1"


class ResultStore:
    """The results file of one sweep, open for appending.

    Args:
        path: The file (created with its header if absent).
        identity: What the task is (:meth:`SweepTask.identity`); an existing file must
            have been written for the same task.

    Raises:
        InputError: The file holds another task's results, a line in its middle is
            broken, a seed is in it twice, or another sweep has it open.
    """

    def __init__(self, path: str | Path, identity: dict[str, Any]) -> None:
        self.path = Path(path)
        # As JSON gives it back (tuples as lists), to compare with the file's.
        self.header = json.loads(json.dumps({"format": FORMAT, "task": identity},
                                            sort_keys=True))
        self.finished: dict[int, TaskResult] = {}
        self.times: dict[int, float] = {}
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: IO[bytes] = open(self.path, "a+b")  # noqa: SIM115 - closed by close()
        try:
            fcntl.flock(self._file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._file.close()
            raise InputError("another sweep is writing this file", path=self.path) from None
        try:
            self._load()
        except BaseException:
            self.close()
            raise

    def _load(self) -> None:
        self._file.seek(0)
        data = self._file.read()
        if not data:
            self._write_line(self.header)
            return
        lines = data.split(b"\n")
        complete, tail = lines[:-1], lines[-1]  # tail: after the last newline
        if not complete:  # the header itself was cut short: nothing else can follow it
            self._cut(0)
            self._write_line(self.header)
            return
        self._check_header(complete[0])
        for number, line in enumerate(complete[1:], start=2):
            self._take(number, line)
        if tail:
            # A kill's half-written last line: dropped, its seed runs again.
            self._cut(len(data) - len(tail))

    def _check_header(self, line: bytes) -> None:
        try:
            header = json.loads(line)
        except ValueError:
            raise InputError("line 1 is no sweep header", path=self.path) from None
        if header != self.header:
            why = _differs(header, self.header)
            raise InputError(f"holds the results of another sweep ({why}): choose a new "
                             "output folder", path=self.path, key="task")

    def _take(self, number: int, line: bytes) -> None:
        try:
            entry = json.loads(line)
            seed, result = entry["seed"], TaskResult.from_json(entry["result"])
            duration = float(entry["time"])
        except (ValueError, KeyError, TypeError, InputError):
            raise InputError(f"line {number} is no result (a line in the middle is never "
                             "half-written by a kill)", path=self.path) from None
        if not isinstance(seed, int) or seed in self.finished:
            raise InputError(f"line {number}: seed {seed!r} is no integer or is there twice",
                             path=self.path)
        self.finished[seed] = result
        self.times[seed] = duration

    def _cut(self, size: int) -> None:
        self._file.truncate(size)
        self._file.flush()
        os.fsync(self._file.fileno())

    def _write_line(self, data: dict[str, Any]) -> None:
        self._file.seek(0, os.SEEK_END)
        self._file.write(json.dumps(data, sort_keys=True).encode() + b"\n")
        self._file.flush()
        os.fsync(self._file.fileno())

    def append(self, seed: int, result: dict[str, Any], duration: float) -> TaskResult:
        """Write one finished seed's line (on disk when this returns).

        Args:
            seed: The seed.
            result: Its result as JSON data (:meth:`TaskResult.to_json`).
            duration: Its computation time [s].

        Returns:
            The result as read back from its line (what every later reader sees).
        """
        line = {"seed": seed, "result": result, "time": duration}
        self._write_line(line)
        # Read back through JSON: the report is made of what the file holds, whoever ran it.
        parsed = TaskResult.from_json(json.loads(json.dumps(result)))
        self.finished[seed] = parsed
        self.times[seed] = duration
        return parsed

    def close(self) -> None:
        """Release the file."""
        if not self._file.closed:
            fcntl.flock(self._file, fcntl.LOCK_UN)
            self._file.close()

    def __enter__(self) -> ResultStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _differs(found: dict[str, Any], wanted: dict[str, Any]) -> str:
    """The first header key whose value differs (dotted, into nested objects), in words."""
    for key in sorted(set(found) | set(wanted)):
        if found.get(key) != wanted.get(key):
            if isinstance(found.get(key), dict) and isinstance(wanted.get(key), dict):
                return f"{key}.{_differs(found[key], wanted[key])}"
            return f"{key} is {found.get(key)!r:.60}, this sweep's {wanted.get(key)!r:.60}"
    return "same"
