"""The tool on the flange: which links may touch a held object, and what it can grip.

Any robot can hold an object once it has a tool: the links that touch the object when it
is held (the jaws, the fingers, a suction cup's body) and, optionally, the widths between
which the tool grips. It is given in ``robot.yaml`` (``tool:``), in a cell's
``scene.yaml`` (``tool:``, for a robot loaded by name or a cell with another tool), or in
Python (``load_robot(..., tool=ToolSpec(contact_links=(...)))``). Vendor fields (Niryo's
tool id) are optional.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pinocchio as pin

from ..errors import ConfigError, FrameNotFound
from ..files._io import as_float, as_str, check_keys, get_key

__all__ = ["ToolSpec", "read_tool", "check_tool"]

#: The keys of a ``tool:`` mapping (robot.yaml and scene.yaml).
TOOL_KEYS = ("name", "contact_links", "open_width", "closed_width", "id")


@dataclass(frozen=True, kw_only=True)
class ToolSpec:
    """The tool mounted on the flange.

    Attributes:
        contact_links: Links allowed to touch a held object (the jaws or fingers and the
            body between them); a held object touching any other link is a collision.
        name: Human-readable tool name.
        open_width: Inner jaw distance fully open [m], or None: the width of a held
            object is then not checked.
        closed_width: Inner jaw distance fully closed [m] (with ``open_width``).
        tool_id: Vendor tool id, or None (Niryo: 11 for Gripper 1; used by no other
            robot).

    Raises:
        ConfigError: No contact link, a width that is not finite, a negative closed
            width, an open width not above the closed one, or only one of the two.
    """

    contact_links: tuple[str, ...]
    name: str = "tool"
    open_width: float | None = None
    closed_width: float | None = None
    tool_id: int | None = None

    def __post_init__(self) -> None:
        links = (self.contact_links,) if isinstance(self.contact_links, str) \
            else tuple(self.contact_links)
        if not links or not all(isinstance(link, str) and link for link in links):
            raise ConfigError(f"expected one or more link names, got {self.contact_links!r}",
                              key="tool.contact_links")
        object.__setattr__(self, "contact_links", links)
        if not isinstance(self.name, str) or not self.name:
            raise ConfigError(f"expected a non-empty name, got {self.name!r}", key="tool.name")
        if (self.open_width is None) != (self.closed_width is None):
            missing = "closed_width" if self.closed_width is None else "open_width"
            raise ConfigError("give both open_width and closed_width [m], or neither",
                              key=f"tool.{missing}")
        if self.open_width is not None and self.closed_width is not None:
            open_w = _width(self.open_width, "tool.open_width")
            closed_w = _width(self.closed_width, "tool.closed_width")
            if open_w <= closed_w:
                raise ConfigError(f"open_width {open_w:g} m must exceed closed_width "
                                  f"{closed_w:g} m", key="tool.open_width")
            object.__setattr__(self, "open_width", open_w)
            object.__setattr__(self, "closed_width", closed_w)
        if self.tool_id is not None and (isinstance(self.tool_id, bool)
                                         or not isinstance(self.tool_id, int)):
            raise ConfigError(f"expected an integer, got {self.tool_id!r}", key="tool.id")

    @property
    def grips_widths(self) -> bool:
        """Whether the tool says between which widths it grips."""
        return self.open_width is not None


def _width(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(float(value)) or float(value) < 0:
        raise ConfigError(f"expected a finite width >= 0 [m], got {value!r}", key=key)
    return float(value)


def read_tool(raw: Any, *, path: Path | None, key: str = "tool") -> ToolSpec:
    """A :class:`ToolSpec` from a ``tool:`` mapping of a YAML file.

    Keys: ``contact_links`` (required), ``name``, ``open_width`` and ``closed_width``
    [m] (both or neither), ``id`` (a vendor tool id).

    Raises:
        ConfigError: Not a mapping, an unknown or missing key, a bad value; names the
            file and the key.
    """
    if not isinstance(raw, dict):
        raise ConfigError("expected a mapping with contact_links (and optionally name, "
                          "open_width, closed_width, id)", path=path, key=key)
    check_keys(raw, TOOL_KEYS, path=path, prefix=key)
    links = get_key(raw, "contact_links", path=path, prefix=key)
    if not isinstance(links, list) or not links:
        raise ConfigError("expected a list of link names", path=path,
                          key=f"{key}.contact_links")
    widths = {}
    for name in ("open_width", "closed_width"):
        if raw.get(name) is not None:
            widths[name] = as_float(raw[name], path=path, key=f"{key}.{name}",
                                    non_negative=True)
    try:
        return ToolSpec(contact_links=tuple(as_str(x, path=path, key=f"{key}.contact_links")
                                            for x in links),
                        name=as_str(raw.get("name", "tool"), path=path, key=f"{key}.name"),
                        tool_id=raw.get("id"), **widths)
    except ConfigError as exc:
        raise ConfigError(exc.reason, path=path,
                          key=(exc.key or key).replace("tool", key, 1)) from None


def check_tool(tool: ToolSpec, model: pin.Model, *, path: Path | None = None,
               key: str = "tool") -> ToolSpec:
    """``tool``, once every contact link is known to be a frame of ``model``.

    Raises:
        FrameNotFound: A contact link the robot does not have (key ``<key>.contact_links``).
        ConfigError: ``tool`` is not a :class:`ToolSpec`.
    """
    if not isinstance(tool, ToolSpec):
        raise ConfigError(f"expected a safepath.ToolSpec, got {type(tool).__name__}",
                          path=path, key=key)
    for link in tool.contact_links:
        if not model.existFrame(link):
            raise FrameNotFound(link, [f.name for f in model.frames], path=path,
                                key=f"{key}.contact_links")
    return tool
