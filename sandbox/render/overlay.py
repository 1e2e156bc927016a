"""Text bands of the animation frames: the heads-up line, the scale bar and the legend.

A frame of :mod:`sandbox.render.animation` has a band at the top (the heads-up line:
scenario, time, collisions so far, recovery strategy) and a band at the bottom (a scale
bar and a legend strip naming each vehicle by its colour and saying what the marks mean:
slots, orange and blue rings, black crosses, red flashes). Text is drawn with Pillow's
bundled FreeType font (no font files needed) at a size that grows with the frame,
:func:`font_px`, without antialiasing so that frames keep to the run's palette.

Drawing text with FreeType costs about 1.5 ms per line, so nothing here draws text per
frame: the bottom band is drawn once and pasted, and :class:`TextStamps` keeps the mask
of every string (and of every digit) it has drawn and pastes it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

from PIL import Image, ImageDraw, ImageFont

__all__ = [
    "LEGEND_NAMES_MAX",
    "MAX_BANDS",
    "Bands",
    "LegendItem",
    "TextStamps",
    "draw_bottom_band",
    "font",
    "font_px",
    "frame_bands",
]

#: Fleets up to this size are named vehicle by vehicle in the legend.
LEGEND_NAMES_MAX = 12
#: Largest fraction of a frame's height the text bands take; a legend that would need
#: more is left out (small frames).
MAX_BANDS = 0.4

Font = ImageFont.ImageFont | ImageFont.FreeTypeFont


def font_px(size: int) -> int:
    """Font size [px] of a frame ``size`` px wide: 2.5 % of it, at least 10 px.

    >>> font_px(640), font_px(320), font_px(1280)
    (16, 10, 32)
    """
    return max(10, int(round(0.025 * size)))


@lru_cache(maxsize=8)
def font(px: int) -> Font:
    """Pillow's bundled font at ``px`` pixels (its bitmap font without FreeType)."""
    try:
        return ImageFont.load_default(size=px)
    except (ImportError, OSError, TypeError):  # Pillow built without FreeType
        loader = getattr(ImageFont, "load_default_imagefont", ImageFont.load_default)
        return loader()


def _bbox(f: Font, text: str) -> tuple[float, float, float, float]:
    """Box of ``text`` drawn without antialiasing (wider than antialiased text)."""
    try:
        return f.getbbox(text, mode="1")
    except TypeError:  # the bitmap font takes no mode
        return f.getbbox(text)


def _length(f: Font, text: str) -> float:
    """Advance [px] of ``text`` drawn without antialiasing."""
    try:
        return float(f.getlength(text, mode="1"))
    except TypeError:
        return float(f.getlength(text))


def _line_height(f: Font) -> int:
    """Height [px] of a line of text of font ``f``."""
    box = _bbox(f, "Ag0|")
    return int(box[3] - min(box[1], 0)) + 1


@dataclass(frozen=True)
class LegendItem:
    """One entry of the legend strip.

    Attributes
    ----------
    kind : str
        The mark drawn: ``"vehicle"`` (a disc of the vehicle's colour), ``"slot"``,
        ``"reference"``, ``"avoid"``, ``"external"``, ``"filter"`` (constrained by
        the safety filter), ``"failed"`` or ``"collision"``.
    label : str
    color : int
        Palette index of a vehicle's colour (for ``"vehicle"``), else unused.
    """

    kind: str
    label: str
    color: int = 0


@dataclass(frozen=True)
class Bands:
    """Layout of the text bands of a frame.

    Attributes
    ----------
    size : int [px]
        Frame width.
    px : int [px]
        Font size.
    line : int [px]
        Height of a line of text.
    top : int [px]
        Height of the heads-up band.
    bottom : int [px]
        Height of the bottom band (scale bar row, then the legend rows).
    rows : tuple of tuple of (LegendItem, x [px])
        The legend items of each row and where each starts.
    """

    size: int
    px: int
    line: int
    top: int
    bottom: int
    rows: tuple[tuple[tuple[LegendItem, int], ...], ...]


def frame_bands(
    size: int, items: Sequence[LegendItem], height: int | None = None
) -> Bands:
    """Lay out the bands of a frame ``size`` px wide with the legend ``items``.

    Items flow left to right and wrap onto new rows; the bottom band holds the scale
    bar row and every legend row. When the bands would take more than
    :data:`MAX_BANDS` of the frame's height (``height``, default ``size``), the
    legend is left out.
    """
    px = font_px(size)
    f = font(px)
    line = _line_height(f)
    mark = _mark_width(px)
    gap, sep, left = max(3, px // 3), px, max(4, int(0.02 * size))
    rows: list[list[tuple[LegendItem, int]]] = [[]]
    x = left
    for item in items:
        width = mark + gap + int(math.ceil(_length(f, item.label)))
        if rows[-1] and x + width > size - left:
            rows.append([])
            x = left
        rows[-1].append((item, x))
        x += width + sep
    rows = [r for r in rows if r]
    top = line + 6
    bar = line + 6
    bottom = bar + len(rows) * (line + 3) + 3
    rows_px = size if height is None else height
    if top + bottom > MAX_BANDS * rows_px:  # a small frame: no legend, not no view
        rows, bottom = [], bar + 3
    return Bands(size, px, line, top, bottom, tuple(tuple(r) for r in rows))


def _mark_width(px: int) -> int:
    """Width [px] of a legend mark for font size ``px``."""
    return max(8, int(round(1.1 * px)))


def draw_bottom_band(
    bands: Bands,
    *,
    bar_m: float,
    bar_px: float,
    white: int,
    black: int,
    marks: dict[str, int],
) -> Image.Image:
    """The bottom band, an ``L`` image of palette indices, ``size`` x ``bottom`` px.

    Parameters
    ----------
    bands : Bands
    bar_m : float [m]
        Length the scale bar stands for.
    bar_px : float [px]
        Its length on screen.
    white, black : int
        Palette indices of the background and of text and lines.
    marks : dict of str to int
        Palette indices of the marks: ``"path"``, ``"orange"``, ``"blue"``, ``"red"``.
    """
    img = Image.new("L", (bands.size, bands.bottom), white)
    draw = ImageDraw.Draw(img)
    draw.fontmode = "1"
    f = font(bands.px)
    left = max(4, int(0.02 * bands.size))
    # Scale bar row.
    y = bands.line // 2 + 3
    x1 = left + bar_px
    thick = max(2, bands.px // 7)
    draw.line([left, y, x1, y], fill=black, width=thick)
    tick = max(3, bands.px // 3)
    draw.line([left, y - tick, left, y + tick // 2], fill=black, width=1)
    draw.line([x1, y - tick, x1, y + tick // 2], fill=black, width=1)
    draw.text((x1 + 6, y), f"{bar_m:g} m", fill=black, font=f, anchor="lm")
    # Legend rows.
    mark = _mark_width(bands.px)
    gap = max(3, bands.px // 3)
    for r, row in enumerate(bands.rows):
        yc = bands.line + 6 + r * (bands.line + 3) + bands.line // 2 + 1
        for item, x in row:
            _draw_mark(draw, item, x, yc, mark, black, white, marks)
            draw.text((x + mark + gap, yc), item.label, fill=black, font=f, anchor="lm")
    return img


def _draw_mark(
    draw: ImageDraw.ImageDraw,
    item: LegendItem,
    x: int,
    yc: int,
    w: int,
    black: int,
    white: int,
    marks: dict[str, int],
) -> None:
    """Draw the mark of a legend item in the box ``[x, x + w]`` centred on ``yc``."""
    r = w / 2.0
    cx = x + r
    box = [cx - 0.7 * r, yc - 0.7 * r, cx + 0.7 * r, yc + 0.7 * r]
    ring = max(2, int(round(0.22 * w)))
    if item.kind == "vehicle":
        draw.ellipse(box, fill=item.color, outline=black, width=1)
    elif item.kind == "slot":
        draw.ellipse(box, outline=marks["path"], width=max(1, ring // 2))
    elif item.kind == "reference":
        draw.line([x, yc, x + 0.4 * w, yc], fill=marks["path"], width=1)
        draw.line([x + 0.6 * w, yc, x + w, yc], fill=marks["path"], width=1)
    elif item.kind in ("avoid", "external", "filter"):
        fills = {"avoid": marks["orange"], "external": marks["blue"]}
        color = fills.get(item.kind, black)
        draw.ellipse([cx - r, yc - r, cx + r, yc + r], fill=color)
        draw.ellipse(box, fill=white, outline=black, width=1)
    elif item.kind == "failed":
        h = 0.7 * r
        draw.line([cx - h, yc - h, cx + h, yc + h], fill=black, width=ring)
        draw.line([cx - h, yc + h, cx + h, yc - h], fill=black, width=ring)
    elif item.kind == "collision":
        rho = 0.5 * r
        draw.ellipse([cx - rho, yc - rho, cx + rho, yc + rho], outline=marks["red"])
        for a in range(8):
            c, s = math.cos(a * math.pi / 4), math.sin(a * math.pi / 4)
            draw.line(
                [cx + 0.7 * r * c, yc + 0.7 * r * s, cx + r * c, yc + r * s],
                fill=marks["red"],
                width=1,
            )


class TextStamps:
    """Masks of drawn strings, pasted onto frames instead of drawing text again.

    Parameters
    ----------
    px : int
        Font size [px].
    """

    def __init__(self, px: int) -> None:
        self.px = px
        self.font = font(px)
        self.line = _line_height(self.font)
        self._masks: dict[str, Image.Image] = {}
        self.digit = int(
            math.ceil(max(_length(self.font, c) for c in "0123456789-"))
        )  # [px] advance of every character of a number: digits do not jitter

    def mask(self, text: str) -> Image.Image:
        """The mask (mode ``1``) of ``text``, drawn once."""
        got = self._masks.get(text)
        if got is None:
            right = max(_bbox(self.font, text)[2], _length(self.font, text))
            width = max(1, int(math.ceil(right)) + 2)
            got = Image.new("1", (width, self.line), 0)
            draw = ImageDraw.Draw(got)
            draw.fontmode = "1"
            draw.text((0, 0), text, fill=1, font=self.font)
            if len(self._masks) > 4096:  # bounded: a cache, not a record
                self._masks.clear()
            self._masks[text] = got
        return got

    def paste(self, img: Image.Image, xy: tuple[int, int], text: str, fill: int) -> int:
        """Paste ``text`` at ``xy`` in palette index ``fill``; return the end x [px].

        The end is where the next text would start, one font size after the last
        character (spaces of the bundled font are narrow).
        """
        m = self.mask(text)
        img.paste(fill, (xy[0], xy[1], xy[0] + m.width, xy[1] + m.height), m)
        return xy[0] + int(math.ceil(_length(self.font, text))) + self.px

    def paste_number(
        self, img: Image.Image, xy: tuple[int, int], text: str, fill: int
    ) -> int:
        """Paste ``text`` one character per fixed advance (digits stay in place)."""
        x, y = xy
        for c in text:
            if c != " ":
                m = self.mask(c)
                off = (self.digit - int(math.ceil(_length(self.font, c)))) // 2
                img.paste(fill, (x + off, y, x + off + m.width, y + m.height), m)
            x += self.digit
        return x
