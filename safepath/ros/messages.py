"""ROS 2 message types without ROS 2: rosbags type stores and native-class lookup.

:func:`typestore` holds the ROS 2 Humble standard types that ship with rosbags plus
:data:`DEFINITIONS`, the types rosbags lacks (control_msgs, Niryo's Ned ROS 2 driver, the
quality-check cell's service: see :mod:`._definitions`); :func:`written_typestore` the
messages safepath writes, with classes generated ahead of time, which both stores share.
:func:`message_factory` hands out either these rosbags classes or, when a sourced ROS 2
workspace is importable, the native ``rclpy`` classes of the same types.
"""

from __future__ import annotations

import array
import functools
import importlib
import logging
import struct
from collections.abc import Iterable, Sequence
from typing import Any, Literal

import numpy as np
from rosbags.serde import SerdeError
from rosbags.typesys import TypesysError
from rosbags.typesys.store import Typestore

from ..errors import InputError, RosError
from ..files._io import check_names
from ._definitions import DEFINITIONS, ROS_DISTRO_STORE, WRITTEN_TYPES, standard_store
from ._type_cache import use_written_classes
from ._writing_store import WritingStore

__all__ = [
    "Backend",
    "DEFINITIONS",
    "MessageFactory",
    "ROS_DISTRO_STORE",
    "WRITTEN_TYPES",
    "deserialize",
    "message_factory",
    "serialize",
    "typestore",
    "written_typestore",
]

logger = logging.getLogger(__name__)

Backend = Literal["auto", "rosbags", "rclpy"]


@functools.lru_cache(maxsize=1)
def written_typestore() -> Typestore:
    """The rosbags type store of the messages safepath writes (:data:`WRITTEN_TYPES`: the
    bags' topics, the arm's and gripper's goals) and every type they nest.

    Its classes are generated ahead of time and kept on disk (:mod:`._type_cache`), so
    a process that writes a bag loads them in milliseconds instead of building the whole
    store of :func:`typestore` (about 0.1 s); they are :func:`typestore`'s classes too.
    Built once and shared.
    """
    from . import _written_types

    return WritingStore(_written_types)


@functools.lru_cache(maxsize=1)
def typestore() -> Typestore:
    """The rosbags type store: ROS 2 Humble standard types plus :data:`DEFINITIONS`.

    The types of :func:`written_typestore` have its classes, so a message built from
    either store is the same class. Built once and shared; do not register conflicting
    types in it.

    Raises:
        RosError: The written classes were generated from other definitions than this
            store's (their cache entry is removed, so the next process makes it again).
    """
    store = standard_store()
    use_written_classes(store, written_typestore())
    return store


def _store_of(typename: str) -> Typestore:
    """The store to (de)serialise ``typename`` with: :func:`written_typestore` when it has
    the type (the same bytes, without building the whole store), else :func:`typestore`."""
    written = written_typestore()
    return written if typename in written.fielddefs else typestore()


def serialize(message: Any, typename: str | None = None) -> bytes:
    """CDR bytes (little endian, with the 4-byte encapsulation header) of a rosbags message.

    Args:
        message: A message built from :func:`typestore` classes.
        typename: Its full type name; defaults to ``message.__msgtype__``.

    Raises:
        RosError: Unknown type or a field that does not fit its type.
    """
    name = typename or getattr(message, "__msgtype__", None)
    if not name:
        raise RosError(f"cannot serialize {type(message).__name__}: not a rosbags message")
    try:
        return bytes(_store_of(name).serialize_cdr(message, name))
    except (KeyError, TypesysError) as exc:
        raise RosError(f"unknown message type '{name}' ({exc})") from None
    except (SerdeError, AttributeError, TypeError, ValueError, OverflowError,
            struct.error) as exc:  # (struct: a number that does not fit its field)
        raise RosError(f"cannot serialize '{name}': {exc}") from None


def deserialize(data: bytes | memoryview, typename: str) -> Any:
    """Inverse of :func:`serialize`.

    Raises:
        RosError: Unknown type or bytes that are not a CDR message of that type.
    """
    try:
        return _store_of(typename).deserialize_cdr(data, typename)
    except (KeyError, TypesysError) as exc:
        raise RosError(f"unknown message type '{typename}' ({exc})") from None
    except (SerdeError, ValueError, IndexError) as exc:
        raise RosError(f"cannot deserialize '{typename}': {exc}") from None


class MessageFactory:
    """Builds messages of one backend: rosbags dataclasses or native ``rclpy`` classes.

    Both take every field as a keyword argument; they differ in how a ``float64[]``
    field is stored (numpy array vs. ``array.array('d')``), which :meth:`floats` hides.

    Attributes:
        backend: ``rosbags`` or ``rclpy``.
    """

    def __init__(self, backend: Literal["rosbags", "rclpy"]):
        self.backend = backend

    def cls(self, typename: str) -> Any:
        """The message class of ``typename`` (``pkg/msg/Name``, ``pkg/srv/Name_Request``...)."""
        if self.backend == "rosbags":
            try:
                return _store_of(typename).types[typename]
            except KeyError:
                raise RosError(f"unknown message type '{typename}'") from None
        return _rclpy_class(typename)

    def new(self, typename: str, **fields: Any) -> Any:
        """A message of ``typename`` with the given fields."""
        return self.cls(typename)(**fields)

    def floats(self, values: Iterable[float] | np.ndarray) -> Any:
        """A ``float64[]`` field value."""
        if self.backend == "rosbags":
            return np.array(values, dtype=np.float64).reshape(-1)
        return array.array("d", (float(v) for v in np.asarray(values, dtype=float).reshape(-1)))

    def float_rows(self, values: np.ndarray) -> list[Any]:
        """``float64[]`` field values, one per row of the 2-D ``values`` (each as
        :meth:`floats` gives it; for rosbags, the rows of one new array)."""
        if self.backend == "rosbags":
            return list(np.array(values, dtype=np.float64, order="C", ndmin=2))
        return [self.floats(row) for row in values]


def _rclpy_class(typename: str) -> Any:
    """Import the native class of ``typename`` from a sourced ROS 2 workspace."""
    package, kind, name = typename.split("/")
    base, _, part = name.rpartition("_") if kind in ("srv", "action") else (name, "", "")
    try:
        module = importlib.import_module(f"{package}.{kind}")
        cls = getattr(module, base)
        return getattr(cls, part) if part else cls
    except (ImportError, AttributeError) as exc:
        raise RosError(f"cannot import '{typename}' for the rclpy backend ({exc})") from None


def message_factory(backend: Backend, typenames: Sequence[str]) -> MessageFactory:
    """The factory of ``backend`` that can build every type of ``typenames``.

    Args:
        backend: ``rosbags`` (always available), ``rclpy`` (needs a sourced ROS 2
            workspace with the message packages) or ``auto`` (``rclpy`` when it and
            every type are importable, else ``rosbags``).
        typenames: The types the caller is about to build.

    Raises:
        RosError: ``rclpy`` asked for but it or one of the types is not importable.
        InputError: Unknown backend name.
    """
    if backend == "rosbags":
        return MessageFactory("rosbags")
    if backend not in ("auto", "rclpy"):
        check_names([backend], ("auto", "rosbags", "rclpy"), path=None, key="backend",
                    what="backend", error=InputError)
    try:
        importlib.import_module("rclpy")
        for name in typenames:
            _rclpy_class(name)
    except (ImportError, RosError) as exc:
        if backend == "rclpy":
            reason = exc if isinstance(exc, RosError) else f"rclpy is not importable ({exc})"
            raise RosError(f"backend 'rclpy' unavailable: {reason}") from None
        logger.debug("rclpy backend unavailable (%s); using rosbags", exc)
        return MessageFactory("rosbags")
    return MessageFactory("rclpy")
