"""A histogram as an inline SVG element: no plotting package, the same bytes every time."""

from __future__ import annotations

from html import escape

from .stats import Distribution

__all__ = ["histogram_svg"]

_W, _H = 560, 220
_LEFT, _RIGHT, _TOP, _BOTTOM = 52, 16, 14, 42


def _num(value: float, other: float | None = None) -> str:
    """A tick's number, short, with the digits that tell it from ``other``."""
    for digits in (4, 6, 9, 17):
        text = f"{value:.{digits}g}"
        if other is None or text != f"{other:.{digits}g}":
            return text
    return text


def histogram_svg(dist: Distribution) -> str:
    """The distribution's histogram: bars, axes, the range and the largest count."""
    head = (f'<svg class="plot" data-key="{escape(dist.key)}" '
            f'width="{_W}" height="{_H}" viewBox="0 0 {_W} {_H}" role="img" '
            f'aria-label="{escape(dist.label)}">')
    if not dist.counts:
        return (head + f'<text x="{_W / 2}" y="{_H / 2}" text-anchor="middle">no finite '
                "value</text></svg>")
    plot_w, plot_h = _W - _LEFT - _RIGHT, _H - _TOP - _BOTTOM
    top = max(dist.counts)
    bar_w = plot_w / len(dist.counts)
    parts = [head, f'<rect x="0" y="0" width="{_W}" height="{_H}" fill="#ffffff"/>']
    for k, count in enumerate(dist.counts):
        h = plot_h * count / top
        x = _LEFT + k * bar_w
        parts.append(f'<rect class="bar" x="{x:.2f}" y="{_TOP + plot_h - h:.2f}" '
                     f'width="{max(bar_w - 1, 0.5):.2f}" height="{h:.2f}" fill="#3b6ea8">'
                     f"<title>{_num(dist.edges[k])} to {_num(dist.edges[k + 1])}: {count}"
                     "</title></rect>")
    base = _TOP + plot_h
    parts += [
        f'<line x1="{_LEFT}" y1="{base}" x2="{_LEFT + plot_w}" y2="{base}" stroke="#333"/>',
        f'<line x1="{_LEFT}" y1="{_TOP}" x2="{_LEFT}" y2="{base}" stroke="#333"/>',
        f'<text x="{_LEFT - 4}" y="{_TOP + 10}" text-anchor="end" font-size="11">{top}</text>',
        f'<text x="{_LEFT - 4}" y="{base}" text-anchor="end" font-size="11">0</text>',
        f'<text x="{_LEFT}" y="{base + 16}" font-size="11">'
        f"{_num(dist.edges[0], dist.edges[-1])}</text>",
        f'<text x="{_LEFT + plot_w}" y="{base + 16}" text-anchor="end" font-size="11">'
        f"{_num(dist.edges[-1], dist.edges[0])}</text>",
        f'<text x="{_LEFT + plot_w / 2}" y="{base + 34}" text-anchor="middle" '
        f'font-size="12">{escape(dist.label)}</text>',
        f'<text x="14" y="{_TOP + plot_h / 2}" text-anchor="middle" font-size="11" '
        f'transform="rotate(-90 14 {_TOP + plot_h / 2})">count</text>',
        "</svg>"]
    return "".join(parts)
