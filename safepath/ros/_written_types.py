"""The classes of the messages safepath writes and of every type they nest.

The body of this module is rosbags' generated type store module for those types
(``FIELDDEFS`` and one dataclass per type, see
:func:`~safepath.ros._definitions.written_source`), read from the on-disk cache
(:mod:`._type_cache`) or made and kept there. Run here, its classes belong to this
module, so they are importable by name in any process (a pickled message reads back).
"""

from __future__ import annotations

from ..errors import RosError
from ._definitions import WRITTEN_TYPES, standard_store, written_source
from ._type_cache import cached_source

_source, _origin = cached_source(lambda: written_source(standard_store()))
exec(compile(_source, _origin, "exec"), globals())  # defines FIELDDEFS and the classes
if not set(WRITTEN_TYPES) <= set(globals().get("FIELDDEFS", ())):
    raise RosError(f"the message classes from {_origin} lack some of {WRITTEN_TYPES}")
