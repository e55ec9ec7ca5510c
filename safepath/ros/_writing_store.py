"""A rosbags type store that generates first the code a bag's writer runs.

rosbags generates 13 functions per message type the first time a store meets it
(serialisers and deserialisers in both byte orders, ROS 1 codes and converters); a
process that writes a bag runs two of them, the size and the little-endian CDR
serialiser, and the rest is about 10 ms of its first write. :class:`WritingStore`
generates those two; the first call of any other code of any type has rosbags generate
every code, as a plain store does. The code run is rosbags' own either way, so the bytes
are the same.
"""

from __future__ import annotations

import dataclasses
from types import ModuleType
from typing import Any

from rosbags.interfaces import Msgdef
from rosbags.serde.cdr import generate_getsize_cdr, generate_serialize_cdr
from rosbags.typesys.base import normalize_fieldname
from rosbags.typesys.store import Typestore

__all__ = ["WritingStore"]


class _Later:
    """A code of a message definition that :class:`WritingStore` has not generated: called,
    it has rosbags generate every code of every type, then runs the one asked for."""

    def __init__(self, store: WritingStore, typename: str, code: str):
        self.store, self.typename, self.code = store, typename, code

    def __call__(self, *args: Any) -> Any:
        self.store.generate_all()
        return getattr(self.store.get_msgdef(self.typename), self.code)(*args)


class WritingStore(Typestore):
    """A rosbags type store whose types get their size and little-endian CDR serialiser
    first, every other code when one is first called (see the module docstring).

    Args:
        base: A type store module (``FIELDDEFS`` and the classes), as rosbags' stores.
    """

    def __init__(self, base: ModuleType):
        super().__init__(base)
        self._all = False

    def generate_all(self) -> None:
        """From now on, a plain rosbags store: every code of a type, generated on first use."""
        self._all = True
        self.cache.clear()

    def get_msgdef(self, typename: str) -> Msgdef[object]:
        """The message definition of ``typename`` (see the class docstring)."""
        msgdef = self.cache.get(typename)  # once per nested message: the short way first
        if msgdef is not None:
            return msgdef
        if self._all:
            return super().get_msgdef(typename)
        entries = [(normalize_fieldname(name), desc)
                   for name, desc in self.fielddefs[typename][1]]
        getsize_cdr, size_cdr = generate_getsize_cdr(entries, self)
        codes: dict[str, Any] = {f.name: _Later(self, typename, f.name)
                                 for f in dataclasses.fields(Msgdef)}
        codes.update(name=typename, fields=entries, cls=self.types[typename],
                     size_cdr=size_cdr, getsize_cdr=getsize_cdr,
                     serialize_cdr_le=generate_serialize_cdr(entries, self, "le"))
        msgdef = self.cache[typename] = Msgdef(**codes)
        return msgdef
