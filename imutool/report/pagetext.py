"""The text of a laid-out report page drawn by one matplotlib artist, for the PDF renderer.

A page of tables holds hundreds of strings; as ``Text`` artists each is laid out twice (``Text._get_layout``
measures it to place it, then the renderer shapes it again to draw it). :class:`PageText` hands each string to
the renderer's ``draw_text`` at the point a ``Text`` with ``va="baseline"`` puts it: the anchor itself for
``ha="left"``, the anchor less the string's width (the renderer's own measurement) for ``ha="right"``, with the
same graphics state. The page's drawing operations are the same as with ``Text`` artists, in the same order;
only the layout pass is gone. Imported only by the PDF rendering (it imports matplotlib).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib import colors as mcolors
from matplotlib import rcParams
from matplotlib.artist import Artist
from matplotlib.font_manager import FontProperties

# one string: x, y (figure fraction), text, font size (pt), weight, colour, horizontal alignment ("left"/"right")
Item = tuple[float, float, str, float, str, str, str]


class PageText(Artist):
    """Strings anchored at figure fractions on their baseline, drawn in the order given (``family`` font)."""

    zorder = 3  # as a Text: above the page's rules and shading

    def __init__(self, items: list[Item], family: str) -> None:
        super().__init__()
        self.items = items
        self.family = family
        self._props: dict[tuple[float, str], FontProperties] = {}

    def _prop(self, size: float, weight: str) -> FontProperties:
        prop = self._props.get((size, weight))
        if prop is None:
            prop = self._props[(size, weight)] = FontProperties(family=self.family, size=size, weight=weight)
        return prop

    def draw(self, renderer: Any) -> None:
        if not self.get_visible() or not self.items:
            return
        fig = self.get_figure(root=True)
        xy = fig.transFigure.transform(np.array([(x, y) for x, y, *_ in self.items], dtype=float))
        widths: dict[tuple[str, float, str], float] = {}
        antialiased = bool(rcParams["text.antialiased"])  # a Text's default
        for (posx, posy), (_, _, s, size, weight, color, ha) in zip(xy.tolist(), self.items, strict=True):
            if not s:
                continue  # a Text draws nothing for ""
            prop = self._prop(size, weight)
            if ha == "right":
                key = (s, size, weight)
                w = widths.get(key)
                if w is None:
                    w = widths[key] = renderer.get_text_width_height_descent(s, prop, ismath=False)[0]
                posx = posx + (0.0 - w)
            elif ha != "left":
                raise ValueError(f"horizontal alignment {ha!r}: left or right")
            gc = renderer.new_gc()
            gc.set_foreground(mcolors.to_rgba(color), isRGBA=True)
            gc.set_alpha(None)
            gc.set_url(None)
            gc.set_antialiased(antialiased)
            gc.set_snap(None)
            gc.set_clip_path(None)
            renderer.draw_text(gc, posx, posy, s, prop, 0.0, ismath=False, mtext=None)
            gc.restore()
        self.stale = False
