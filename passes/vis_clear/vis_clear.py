"""Visibility-buffer clear: the 64-bit depth-and-id words the atomic visbuffer writes."""

from typing import Annotated

from rfw.authoring import Buffer, ComputePass, Range, Settings, SettingsError, register_pass

WORD = 8  # bytes of one pixel's word: depth bits high, the id's complement low


@register_pass("vis_clear")
class VisClearPass(ComputePass):
    """Fills ``ids`` with all ones (the largest word: no surface yet) for a ``visbuffer``
    with ``write = "atomic"``, which keeps the smallest (depth, complemented id) per pixel
    with 64-bit atomics instead of writing a color attachment. The buffer holds
    ``max_pixels`` words (a larger output fails naming the setting); a compute shader fills
    it at memory speed where raster writes are slow (the H200's).
    """

    shader = "vis_clear.comp.glsl"
    backend = "vk"
    replay = "auto"

    class Params(Settings):
        # the largest output; at most what one row of 65,535 workgroups of 256 reaches
        max_pixels: Annotated[int, Range(1, 65535 * 256)] = 3840 * 2160

    def declare(self):
        return {}, {"ids": Buffer(WORD * self.params.max_pixels, usage=("storage",),
                                  desc="per pixel: depth bits << 32 | ~id, all ones: none")}

    def replay_key(self, ctx):
        # and the pixel count: the size the scene's camera was set for
        return ctx.scene.size

    def record(self, ctx) -> None:
        size = ctx.scene.size
        check_pixels(self.name, self.params.max_pixels, size)
        ctx.dispatch(threads=(size[0] * size[1],), ids=ctx.buffer("ids"))


def check_pixels(pass_name: str, max_pixels: int, size: tuple[int, int]) -> None:
    """A SettingsError unless ``size`` fits ``max_pixels`` words."""
    if size[0] * size[1] > max_pixels:
        raise SettingsError(f"pass '{pass_name}': {size[0]}x{size[1]} is more than the "
                            f"visibility buffer's max_pixels ({max_pixels:,}): raise the "
                            "vis_clear pass's setting 'max_pixels'")
