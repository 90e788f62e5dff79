"""Points and lines: the scene's point and line primitives, one pixel wide, unlit."""

from typing import ClassVar

from rfw.authoring import Attachment, DepthAttachment, RenderPass, Slot, register_pass


@register_pass("points_lines")
class PointsLinesPass(RenderPass):
    """Draws the scene's strokes (``Scene.strokes``: glTF POINTS, LINES, LINE_LOOP and
    LINE_STRIP primitives, point clouds and polylines of mesh files) over a shaded image.

    Lines are one pixel wide and points one pixel (``gl_PointSize = 1``), tested against
    the scene's depth with ``less`` and writing none. Every stroke is unlit, as glTF 2.0
    section 3.7.2.1 asks of points and lines without normals; those with normals are drawn
    unlit as well (their NORMAL is read and kept, not lit): ``base colour factor x COLOR_0
    + emissive factor``, with alpha 1 where anything is drawn. Textures are not sampled (the
    loader warns), alpha masks cut with the material's cutoff, and blended materials are
    drawn opaque. On a scene without points or lines the pass is left out of the run (no
    timing row).
    """

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "points_lines"
    inputs: ClassVar[dict[str, Slot]] = {
        "color": Attachment(desc="the shaded image, drawn over in place"),
        "depth": DepthAttachment(None, read_only=True,
                                 desc="the scene's depth, tested and not written"),
    }
    outputs: ClassVar[dict[str, Slot]] = {}
    scene_needs = "strokes"  # left out of a run whose scene has no points or lines

    def record(self, ctx) -> None:
        for topology in ("line-list", "point-list"):
            ctx.draw_scene(color=[("color", None)], depth=("depth", None), depth_write=False,
                           alpha=("OPAQUE", "MASK", "BLEND"), topology=topology)
