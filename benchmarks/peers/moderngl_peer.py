"""moderngl on a headless EGL context: rfw's ``flat`` technique, the scene in one draw.

GPU time from a GL_TIME_ELAPSED query around each frame's clear and draw; wall time with a
glFinish at the end of the frame."""

from __future__ import annotations

from typing import Any

import numpy as np

from .common import AMBIENT, Geometry, Unavailable, time_frames

# passes/flat's shading: lambert per vertex, interpolated, stored unencoded
VERT = """
#version 330
uniform mat4 u_viewproj; uniform vec3 u_light; uniform float u_ambient;
in vec3 in_pos; in vec3 in_nrm; in vec3 in_col;
out vec3 v_col;
void main() {
    float lam = max(dot(normalize(in_nrm), u_light), 0.0);
    v_col = in_col * (u_ambient + (1.0 - u_ambient) * lam);
    gl_Position = u_viewproj * vec4(in_pos, 1.0);
}
"""
FRAG = """
#version 330
in vec3 v_col; out vec4 f_color;
void main() { f_color = vec4(v_col, 1.0); }
"""


def measure(geo: Geometry, camera: Any, width: int, height: int, *, frames: int,
            warmup: int) -> dict[str, Any]:
    try:
        import moderngl
    except ImportError as e:
        raise Unavailable(f"moderngl is not installed ({e}); pip install '.[peers]'") from None
    try:
        ctx = moderngl.create_standalone_context(backend="egl")
    except Exception as e:
        raise Unavailable(f"no EGL context: {e}") from None
    try:
        # rfw culls back faces (counter-clockwise fronts, as GL's default)
        ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        prog = ctx.program(vertex_shader=VERT, fragment_shader=FRAG)
        vp = camera.projection(width / height).astype(np.float64) @ camera.view()
        # opengl clip z is -w..w: rfw's matrix maps to 0..1, remap z' = 2z - w
        vp = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 2, -1], [0, 0, 0, 1]]) @ vp
        prog["u_viewproj"].write(vp.T.astype("f4").tobytes())
        prog["u_light"].value = tuple(float(v) for v in geo.light_dir)
        prog["u_ambient"].value = AMBIENT
        data = np.hstack([geo.positions, geo.normals, geo.colors]).astype("f4")
        vbo = ctx.buffer(data.tobytes())
        ibo = ctx.buffer(geo.indices.astype("u4").tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "3f 3f 3f", "in_pos", "in_nrm", "in_col")],
                               index_buffer=ibo, index_element_size=4)
        fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((width, height))],
                              depth_attachment=ctx.depth_renderbuffer((width, height)))
        query = ctx.query(time=True)
        gpu: list[float] = []

        def frame() -> None:
            fbo.use()
            with query:
                fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
                vao.render(moderngl.TRIANGLES)
            ctx.finish()
            gpu.append(query.elapsed * 1e-6)  # ns

        wall = time_frames(frame, frames=frames, warmup=warmup)
        gpu = gpu[-frames:]
        rgb = np.frombuffer(fbo.read(components=3), np.uint8).reshape(height, width, 3)[::-1]
        info = ctx.info
        return {"frame_ms": wall, "gpu_ms": gpu, "timing": "GL_TIME_ELAPSED query (gpu); "
                "wall with glFinish", "image": rgb.copy(),
                "version": moderngl.__version__,
                "device": f"{info['GL_RENDERER']} (OpenGL {info['GL_VERSION']})"}
    finally:
        ctx.release()
