"""The viewer's text overlay: the status panel, the key bar, a centred
message and the "building" badge, drawn by Pillow into small textures that
are rewritten only when their text changes, and blended over the scene.

The text itself (:func:`status_lines`, :func:`key_lines`, :func:`wrap`) is
plain string work on a Pillow font; only :class:`Overlay` touches OpenGL.
"""

from __future__ import annotations

from collections.abc import Sequence

import moderngl
import numpy as np

from aniso3d.app.viewer.scene import Frame
from aniso3d.app.viewer.state import CONTROLS, METHOD_LABELS, METHODS, ViewState
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.frame import DrawStats
from aniso3d.rendering.select import describe_stats

Color = tuple[int, int, int]
#: Text lines: (text, RGB colour), top line first.
Lines = Sequence[tuple[str, Color]]

WHITE, GREY, YELLOW, RED, GREEN = (
    (235, 235, 235),
    (160, 165, 175),
    (255, 205, 80),
    (255, 120, 110),
    (150, 220, 150),
)
#: Pixels between the window's edge and a panel.
MARGIN = 10
#: Seconds between updates of the frame-time figures (readable, not flickering).
TIMING_PERIOD = 0.25


def load_font(px: int):
    """A monospaced TrueType font of ``px`` pixels where one is installed, else Pillow's default."""
    from PIL import ImageFont

    for name in ("DejaVuSansMono.ttf", "DejaVuSans.ttf"):
        try:
            return ImageFont.truetype(name, px)
        except OSError:
            continue
    try:
        return ImageFont.load_default(size=px)
    except TypeError:  # Pillow < 10.1: one bitmap size
        return ImageFont.load_default()


def text_panel(lines: Lines, font, pad: int = 8, background=(20, 22, 28, 190)) -> np.ndarray:
    """(H, W, 4) uint8 RGBA image of coloured text lines on a translucent panel,
    top row first."""
    from PIL import Image, ImageDraw

    probe = ImageDraw.Draw(Image.new("RGBA", (1, 1)))
    ascent, descent = font.getmetrics() if hasattr(font, "getmetrics") else (12, 3)
    line_h = ascent + descent + 2
    width = max((probe.textlength(text, font=font) for text, _ in lines), default=0)
    w, h = int(width) + 2 * pad, line_h * len(lines) + 2 * pad - 2
    img = Image.new("RGBA", (max(w, 1), max(h, 1)), (0, 0, 0, 0))
    draw = ImageDraw.Draw(img)
    draw.rounded_rectangle([0, 0, w - 1, h - 1], radius=min(6, pad), fill=background)
    for i, (text, color) in enumerate(lines):
        draw.text((pad, pad + i * line_h), text, font=font, fill=(*color, 255))
    return np.asarray(img)


# ------------------------------------------------------------------------ text


def status_lines(name: str, state: ViewState, frame: Frame, timing: str, size: tuple[int, int],
                 building: str | None, notice: tuple[str, Color] | None) -> list[tuple[str, Color]]:  # fmt: skip
    """The status panel: input, renderer, settings, frame time and window
    size, what is drawn, the build under way and the latest notice."""
    s, kind = state.settings, state.kind
    lines = [(f"aniso3d view · {name}", WHITE)]
    names = "  ".join(
        (f"[{i}:{METHOD_LABELS[m]}]" if m == s.method else f" {i}:{METHOD_LABELS[m]} ")
        for i, m in enumerate(METHODS, 1)
    )
    lines.append((f"renderer  {names}", WHITE))
    vox = f"{s.resolution}³ K={s.directions}" + {"mesh": "", "scene": " per asset"}.get(kind, " (fixed)")
    if kind == "points":
        vox = "n/a (point cloud)"
    lines.append((f"splat {s.splat} · quality {s.quality} · placement {s.placement}", GREY))
    lines.append((f"voxels {vox}" + (" · turntable" if s.turntable else ""), GREY))
    lines.append(((timing or "frame –") + f" · {size[0]}x{size[1]}", WHITE))
    if frame.shown is not None:
        old = " (previous settings)" if frame.state == "stale" else ""
        lines.append((f"drawing {frame.shown.counts}{old}", WHITE))
        lines += [(text, WHITE) for text in stats_lines(frame.stats)]
    if building:
        lines.append((building, YELLOW))
    if notice is not None:
        lines.append(notice)
    return lines


def stats_lines(stats: DrawStats | None) -> list[str]:
    """What the last draw says it drew, where it drew from a pyramid or drew
    a scene's instances: the primitives and levels of the frame, and the
    selection (:func:`~aniso3d.rendering.select.describe_stats`: for a scene,
    the instances drawn, culled and per level); nothing otherwise."""
    scene = stats is not None and bool(stats.lod) and "instances" in stats.lod
    if stats is None or not (stats.levels or scene):
        return []
    levels = " ".join(str(level) for level in stats.levels)
    line = f"this frame {stats.drawn:,} {stats.unit}"
    if stats.levels:
        line += f" from level{'s' if len(stats.levels) > 1 else ''} {levels}"
    lines = [line]
    lod = describe_stats(stats.lod)
    return lines + ([lod] if lod else [])


def key_lines(font, width_px: float) -> list[tuple[str, Color]]:
    """The controls as a few lines of "key action" items that fit ``width_px``."""
    lines, line = [], ""
    for keys, action in CONTROLS:
        item = f"{keys} {action}"
        joined = f"{line}   {item}" if line else item
        if line and font.getlength(joined) > width_px:
            lines.append(line)
            joined = item
        line = joined
    lines.append(line)
    return [(ln, GREY) for ln in lines]


def wrap(text: str, font, width_px: float, color: Color) -> list[tuple[str, Color]]:
    """Split a long message into lines of whole words that fit ``width_px``."""
    per_line = max(20, int(width_px / max(font.getlength("M"), 1)) - 4)
    lines, line = [], ""
    for word in text.split():
        if line and len(line) + 1 + len(word) > per_line:
            lines.append(line)
            line = word
        else:
            line = f"{line} {word}".strip()
    lines.append(line)
    return [(ln, color) for ln in lines]


# ------------------------------------------------------------------------ GL


class _Slot:
    """A texture holding one overlay panel, rewritten when its text changes."""

    def __init__(self):
        self.key = None
        self.tex = None
        self.size = (0, 0)


class Overlay:
    """Screen rectangles in the window's default framebuffer: the scene image
    (:meth:`blit`) and text panels (:meth:`place`). ``scale`` is framebuffer
    pixels per window unit (2 on a high-DPI screen)."""

    def __init__(self, gl: GLContext, scale: float = 1.0):
        self.gl = gl
        self.font = load_font(int(round(13 * scale)))
        self.big_font = load_font(int(round(16 * scale)))
        self._quad = gl.program("viewer_quad.vert", "viewer_quad.frag")
        self._vao = gl.track(gl.ctx.vertex_array(self._quad, []))
        self._slots: dict[str, _Slot] = {}
        self._timing = ("", -1.0)

    def timing(self, frame_ms: float | None, now: float) -> str:
        """"frame 12.3 ms · 81 fps", updated every :data:`TIMING_PERIOD` seconds."""
        text, updated = self._timing
        if now - updated > TIMING_PERIOD:
            if frame_ms is not None:
                text = f"frame {frame_ms:.1f} ms · {1000.0 / max(frame_ms, 1e-3):.0f} fps"
            self._timing = (text, now)
        return text

    def begin(self, size: tuple[int, int]) -> None:
        """Draw into the window's whole framebuffer of ``size`` (w, h), no depth, no blending."""
        ctx = self.gl.ctx
        ctx.screen.use()
        ctx.viewport = (0, 0, *size)
        ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE | moderngl.BLEND)

    def blend(self, on: bool) -> None:
        """Blend what follows over what is drawn (text panels over the scene)."""
        ctx = self.gl.ctx
        if on:
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        else:
            ctx.disable(moderngl.BLEND)

    def blit(self, tex, px: tuple[float, float, float, float], screen: tuple[int, int], flip: bool,
             opaque: bool) -> None:  # fmt: skip
        """Draw ``tex`` over pixels px = (left, top, right, bottom), y down, of a screen (w, h)."""
        sw, sh = screen
        x0, y0, x1, y1 = px
        GLContext.set_uniforms(self._quad, {
            "u_rect": (2 * x0 / sw - 1, 1 - 2 * y1 / sh, 2 * x1 / sw - 1, 1 - 2 * y0 / sh),
            "u_flip": 1 if flip else 0,
            "u_opaque": 1 if opaque else 0,
            "u_tex": 0,
        })  # fmt: skip
        tex.use(0)
        self._vao.render(moderngl.TRIANGLE_STRIP, vertices=4)

    def _panel(self, slot_name: str, lines: Lines, font) -> _Slot:
        slot = self._slots.setdefault(slot_name, _Slot())
        key = (tuple(lines), id(font))
        if slot.key != key:
            img = text_panel(list(lines), font)
            h, w = img.shape[:2]
            if slot.tex is None or slot.size != (w, h):
                if slot.tex is not None:
                    self.gl.free(slot.tex)
                slot.tex = self.gl.track(self.gl.ctx.texture((w, h), 4, img.tobytes()))
                slot.tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
                slot.size = (w, h)
            else:
                slot.tex.write(img.tobytes())
            slot.key = key
        return slot

    def place(self, slot_name: str, lines: Lines, screen: tuple[int, int], x: int | None, y: int | None,
              big: bool = False) -> tuple[int, int]:  # fmt: skip
        """Draw a text panel; x, y >= 0 from the left/top, < 0 from the
        right/bottom, None centred. Returns the panel's size."""
        slot = self._panel(slot_name, lines, self.big_font if big else self.font)
        w, h = screen
        pw, ph = slot.size
        left = (w - pw) // 2 if x is None else x if x >= 0 else w + x - pw
        top = (h - ph) // 2 if y is None else y if y >= 0 else h + y - ph
        self.blit(slot.tex, (left, top, left + pw, top + ph), screen, flip=True, opaque=False)
        return pw, ph
