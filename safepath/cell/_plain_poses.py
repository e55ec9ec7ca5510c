"""A fast reader for the plain layouts of ``poses.yaml``, giving exactly what YAML gives.

A file of many poses is almost all lines ``name: [number, ...]`` (nested under
``poses:`` as :func:`~safepath.cell.poses.dump_poses` writes them, or flat as the
recorder appends them). PyYAML builds a node per value before the values themselves
(seconds and hundreds of MB for 30,000 poses); these lines are read here with one
pattern each instead. Only a file that is nothing but such lines is read here, and
only with names and numbers that YAML 1.1 reads the same way (a name that YAML reads
as text, a decimal integer or a float with a point); anything else (comments, blank
lines, TCP poses, quoted names, ``1e-05``, a name given twice...) returns None and the
whole file goes to YAML, which reads it or names what is wrong.
"""

from __future__ import annotations

import re

__all__ = ["read_plain"]

_LINE = re.compile(r"(  )?([A-Za-z_][A-Za-z0-9_\-]*): \[([-+.0-9e, ]*)\]")
#: What PyYAML's resolver reads as an int (decimal, no leading zero) or a float (with a
#: point; an exponent with its sign), and Python's int() and float() read the same way.
_INT = re.compile(r"-?(?:0|[1-9][0-9]*)")
_FLOAT = re.compile(r"-?[0-9]+\.[0-9]+(?:e[-+][0-9]+)?")
#: Names YAML 1.1 reads as booleans or null (and near misses, left to YAML).
_NOT_TEXT = frozenset({"yes", "no", "true", "false", "on", "off", "null", "y", "n"})


def read_plain(text: str) -> dict[str, object] | None:
    """What YAML reads from ``text`` if it is only plain pose lines, else None."""
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    top: dict[str, object] = {}
    nested: dict[str, object] | None = None
    if lines and lines[0] == "poses:":
        nested = top["poses"] = {}
        lines = lines[1:]
        if not lines:
            return None
    for line in lines:
        m = _LINE.fullmatch(line)
        if m is None or m[2].lower() in _NOT_TEXT or len(m[2]) > 1000:  # YAML: 1024 max
            return None
        indented, name = m[1] is not None, m[2]
        if indented and (nested is None or len(top) > 1):
            return None  # an indented line after a top-level one: left to YAML
        values = _numbers(m[3])
        into = nested if indented else top
        if values is None or into is None or name in into:
            return None
        into[name] = values
    return top or None


def _numbers(text: str) -> list[int | float] | None:
    """The numbers of a flow list's inside, as YAML reads them, or None."""
    out: list[int | float] = []
    for token in text.split(","):
        token = token.strip(" ")
        if _FLOAT.fullmatch(token):
            out.append(float(token))
        elif _INT.fullmatch(token):
            out.append(int(token))
        else:
            return None
    return out
