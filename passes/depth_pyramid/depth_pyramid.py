"""Hierarchical depth (Hi-Z) pyramid: max-reduced depth mips for occlusion culling."""

from rfw.authoring import ComputePass, Part, Settings, Step, Tex2D, register_pass


@register_pass("depth_pyramid")
class DepthPyramidPass(ComputePass):
    """Depth (0 near, 1 far) reduced to a mip chain of its FARTHEST value per texel (max), as
    conservative occlusion culling needs: no geometry inside a texel's footprint is farther
    than the texel. Mip 0 is the depth buffer's size (a power-of-two floor cannot be
    expressed by the graph's size rules); each level is the floor half of the one below, and
    a texel on an odd edge also takes the third source row/column, so every level-0 pixel
    ``p`` lies in level ``L``'s texel ``min(p >> L, size_L - 1)``. One dispatch per level,
    each level written and read through its own single-mip storage view.

    Each level is a declared step (level L reads mip L - 1, writes mip L): the compiled
    graph plans the barrier on mip L - 1 before level L, as between passes."""

    # its commands depend on nothing but its settings, slot resources and scene
    replay = "auto"
    shader = "depth_pyramid.comp.glsl"
    inputs = {"depth": Tex2D(desc="scene depth, 0 near 1 far")}
    outputs = {"pyramid": Tex2D("r32float", size_of="depth",
                                desc="max-depth mip chain, level 0 at depth's size")}

    class Params(Settings):
        levels: int = 6  # mip levels (at most floor(log2(max(width, height))) + 1)

    def _levels(self) -> int:
        return max(1, int(self.params.levels))

    def declare(self):
        outs = dict(self.outputs)
        outs["pyramid"] = outs["pyramid"].with_(mips=self._levels())
        return dict(self.inputs), outs

    def steps(self) -> tuple[Step, ...]:
        first = Step("level 0", reads="depth", writes=Part("pyramid", mips=(0, 1)))
        return (first, *(Step(f"level {lv}", reads=Part("pyramid", mips=(lv - 1, 1)),
                              writes=Part("pyramid", mips=(lv, 1)))
                         for lv in range(1, self._levels())))

    def record(self, ctx) -> None:
        w, h = ctx.extent("pyramid")
        ctx.step(0)
        ctx.dispatch(threads=(w, h), defines={"FROM_DEPTH": 1}, t_depth=ctx.sampled("depth"),
                     o_dst=ctx.storage("pyramid", mip=0))
        for level in range(1, self._levels()):
            ctx.step(level)
            ctx.dispatch(threads=(max(1, w >> level), max(1, h >> level)),
                         i_src=ctx.storage("pyramid", mip=level - 1),
                         o_dst=ctx.storage("pyramid", mip=level))
