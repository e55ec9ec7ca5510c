"""What crosses the pipe between the caller and a planner worker.

Exceptions are not sent as pickles: several safepath errors take keyword-only
arguments in their constructors (``VerificationError``, ``RobotNotFound``,
``FrameNotFound``), which the default exception pickling cannot rebuild, and
``IKError`` would come back with its message extended twice. Instead an error travels
as an :class:`ErrorRecord` (class path, ``args``, attributes, formatted traceback) and
is rebuilt without calling its constructor, so the caller gets the same class with the
same message and the same evidence attributes.
"""

from __future__ import annotations

import functools
import importlib
import logging
import pickle
import traceback
from pathlib import Path
from typing import Any, NamedTuple

from ..errors import SafepathError

__all__ = ["WorkerError", "ErrorRecord", "encode_error", "decode_error", "picklable_record"]


class WorkerError(SafepathError):
    """The planner worker process died, could not start, or the planner is closed.

    Attributes:
        reason: What happened.
        pid: Process id of the worker, if one was running.
        exitcode: Its exit code (negative: the signal that ended it), if known.
    """

    def __init__(self, reason: str, *, pid: int | None = None, exitcode: int | None = None):
        self.reason = reason
        self.pid = pid
        self.exitcode = exitcode
        super().__init__(reason)

    def __reduce__(self) -> tuple[Any, ...]:
        return (_rebuild, (type(self), self.args, dict(self.__dict__)))


class RemoteTraceback(Exception):
    """Carries the worker's formatted traceback as the ``__cause__`` of a rebuilt error."""

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self.text = text

    def __str__(self) -> str:
        return f"\n\"\"\"\n{self.text}\"\"\""


class ErrorRecord(NamedTuple):
    """An exception raised in the worker, in a form that always pickles.

    Attributes:
        module: Module of the exception class.
        qualname: Qualified name of the class in that module.
        args: The exception's ``args`` (its message for safepath errors).
        state: Its attributes (the evidence); unpicklable ones as their ``repr``.
        text: ``str()`` of the exception.
        traceback: The formatted traceback in the worker.
    """

    module: str
    qualname: str
    args: tuple[Any, ...]
    state: dict[str, Any]
    text: str
    traceback: str


def _picklable(value: Any) -> Any:
    try:
        pickle.dumps(value)
    except Exception:  # noqa: BLE001 - anything unpicklable travels as its repr
        return repr(value)
    return value


def encode_error(exc: BaseException) -> ErrorRecord:
    """Describe ``exc`` so that :func:`decode_error` can rebuild it in another process."""
    cls = type(exc)
    return ErrorRecord(
        module=cls.__module__,
        qualname=cls.__qualname__,
        args=tuple(_picklable(a) for a in exc.args),
        state={k: _picklable(v) for k, v in vars(exc).items()},
        text=str(exc),
        traceback="".join(traceback.format_exception(cls, exc, exc.__traceback__)),
    )


def _rebuild(cls: type[BaseException], args: tuple[Any, ...], state: dict[str, Any]
             ) -> BaseException:
    """An instance of ``cls`` with these ``args`` and attributes, without its __init__."""
    err = cls.__new__(cls, *args)
    err.args = args
    err.__dict__.update(state)
    return err


def decode_error(record: ErrorRecord) -> BaseException:
    """The exception described by ``record``: the same class, message and attributes.

    A class that cannot be imported or rebuilt here becomes a :class:`WorkerError`
    naming it. The worker's traceback is attached as ``__cause__``.
    """
    err: BaseException
    try:
        module = importlib.import_module(record.module)
        cls = functools.reduce(getattr, record.qualname.split("."), module)
        if not (isinstance(cls, type) and issubclass(cls, BaseException)):
            raise TypeError(f"{record.qualname} is not an exception class")
        err = _rebuild(cls, record.args, record.state)
    except Exception:  # noqa: BLE001 - any failure to rebuild falls back to WorkerError
        err = WorkerError(f"{record.qualname} in the planner worker: {record.text}")
    err.__cause__ = RemoteTraceback(record.traceback)
    return err


def picklable_record(record: logging.LogRecord) -> logging.LogRecord:
    """A copy of a log record that pickles: message formatted, exception as text."""
    out = logging.makeLogRecord(dict(record.__dict__))
    out.msg = record.getMessage()
    out.args = None
    if record.exc_info:
        out.exc_text = "".join(traceback.format_exception(*record.exc_info))
    out.exc_info = None
    for key, value in list(out.__dict__.items()):
        if isinstance(value, Path):
            out.__dict__[key] = str(value)
        else:
            out.__dict__[key] = _picklable(value)
    return out
