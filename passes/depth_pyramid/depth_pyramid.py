"""Hierarchical depth (Hi-Z) pyramid: max-reduced depth mips for occlusion culling."""

from rfw import ComputePass, Settings, Tex2D, register_pass
from rfw.graph.sync import State

_WRITE = State(None, frozenset({"COMPUTE_SHADER"}), frozenset({"SHADER_STORAGE_WRITE"}))
_READ = State(None, frozenset({"COMPUTE_SHADER"}), frozenset({"SHADER_STORAGE_READ"}))


@register_pass("depth_pyramid")
class DepthPyramidPass(ComputePass):
    """Depth (0 near, 1 far) reduced to a mip chain of its FARTHEST value per texel (max), as
    conservative occlusion culling needs: no geometry inside a texel's footprint is farther
    than the texel. Mip 0 is the depth buffer's size (a power-of-two floor cannot be
    expressed by the graph's size rules); each level is the floor half of the one below, and
    a texel on an odd edge also takes the third source row/column, so every level-0 pixel
    ``p`` lies in level ``L``'s texel ``min(p >> L, size_L - 1)``. One dispatch per level,
    each level written and read through its own single-mip storage view.

    Barriers: the compiled graph plans barriers between passes only. Inside this pass (and
    only for its own mip chain) it records one compute-write -> compute-read memory barrier
    between consecutive level dispatches, so level L's writes are visible to level L+1's
    reads; the image stays in GENERAL throughout, as the plan has it."""

    shader = "depth_pyramid.comp.glsl"
    backend = "vk"
    inputs = {"depth": Tex2D(desc="scene depth, 0 near 1 far")}
    outputs = {"pyramid": Tex2D("r32float", size_of="depth",
                                desc="max-depth mip chain, level 0 at depth's size")}

    class Params(Settings):
        levels: int = 6  # mip levels (at most floor(log2(max(width, height))) + 1)

    def declare(self):
        outs = dict(self.outputs)
        outs["pyramid"] = outs["pyramid"].with_(mips=max(1, int(self.params.levels)))
        return dict(self.inputs), outs

    def record(self, ctx) -> None:
        from vkext.commands import barrier

        w, h = ctx.extent("pyramid")
        levels = ctx.texture("pyramid").mips
        ctx.dispatch(threads=(w, h), defines={"FROM_DEPTH": 1}, t_depth=ctx.sampled("depth"),
                     o_dst=ctx.storage("pyramid", mip=0))
        for level in range(1, levels):
            # the one in-pass barrier: level - 1 written above, read below
            barrier(ctx.cmd, memory_barriers=[(_WRITE, _READ)])
            ctx.dispatch(threads=(max(1, w >> level), max(1, h >> level)),
                         i_src=ctx.storage("pyramid", mip=level - 1),
                         o_dst=ctx.storage("pyramid", mip=level))
