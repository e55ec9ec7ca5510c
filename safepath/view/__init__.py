"""Browser review of a cell's motions (viser): play, check, edit, re-plan, save.

``safepath view SCENE`` opens a :class:`ReviewSession`. Importing this package is
cheap: viser and the session load on first use of :class:`ReviewSession` (the options
and the errors load without viser).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .access import AccessDenied
    from .options import ViewOptions
    from .session import ReviewSession, ShownState
    from .store import PosesChanged

__all__ = ["AccessDenied", "PosesChanged", "ReviewSession", "ShownState", "ViewOptions"]

_MODULES = {"ReviewSession": "session", "ShownState": "session", "ViewOptions": "options",
            "AccessDenied": "access", "PosesChanged": "store"}


def __getattr__(name: str) -> Any:
    if name in _MODULES:
        import importlib

        return getattr(importlib.import_module(f".{_MODULES[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
