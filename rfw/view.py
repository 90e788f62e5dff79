"""``rfw view``: a live window (glfw through rendercanvas) with camera, toggles and timings.

Mouse drag orbits, wheel zooms, W/A/S/D/Q/E move. Keys 1-9 toggle the config's passes in
order, V cycles the first variant (Shift+V the next variant group), R reloads shaders, P
prints the per-pass table. Shaders are also reloaded whenever their source changes: the
pipeline cache is keyed by the preprocessed source's hash.
"""

from __future__ import annotations

import math
import os
import statistics
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from .config import Config, apply_overrides, build
from .errors import RfwError
from .frame import camera_for, load_scene_for
from .graph import GraphError, compile

_BLIT = """
@group(0) @binding(0) var t: texture_2d<f32>;

struct V { @builtin(position) p: vec4f, @location(0) uv: vec2f };

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> V {
    // one triangle covering the screen
    let uv = vec2f(f32((i << 1u) & 2u), f32(i & 2u));
    return V(vec4f(uv * vec2f(2.0, -2.0) + vec2f(-1.0, 1.0), 0.0, 1.0), uv);
}

@fragment
fn fs_main(v: V) -> @location(0) vec4f {
    let size = vec2f(textureDimensions(t));
    // the graph output is display-encoded already: write it as is
    return textureLoad(t, vec2i(min(v.uv * size, size - 1.0)), 0);
}
"""


class Viewer:
    """Owns the window, the device, the scene and the executor of the current config."""

    def __init__(self, cfg: Config, *, scene: Any = None, script: list[str] = (),
                 frames: int | None = None, report_every: int = 60, canvas: Any = None):
        from rendercanvas.glfw import RenderCanvas, loop

        from .backends.gpu_scene import GpuScene
        from .backends.wgpu_backend import Device

        self.cfg = cfg
        self.loop = loop
        # a bad config or scene fails here, before a window opens
        compile(build(cfg).graph)
        self.scene = load_scene_for(cfg, scene)
        self.camera = camera_for(cfg, self.scene)
        self.canvas = canvas or RenderCanvas(size=cfg.size, title=f"rfw: {cfg.name}",
                                             update_mode="continuous")
        self.device = Device()
        self.gpu_scene = GpuScene(self.device.device, self.scene, self.camera)
        self.context = self.canvas.get_wgpu_context()
        self.format = self.context.get_preferred_format(self.device.adapter)
        self.context.configure(device=self.device.device, format=self.format)
        self.script = list(script)
        self.frames_left = frames
        self.report_every = report_every
        self.frame_count = 0
        self.executor = None
        self.log: list[str] = []
        self._blit = self._blit_pipeline()
        self._rebuild()
        self.canvas.add_event_handler(self._on_event, "key_down", "pointer_move", "wheel",
                                      "pointer_down", "resize")
        self._drag: tuple[float, float] | None = None

    # building -----------------------------------------------------------------------------
    def _blit_pipeline(self) -> Any:
        dev = self.device.device
        module = dev.create_shader_module(code=_BLIT, label="rfw:blit")
        return dev.create_render_pipeline(
            layout="auto", vertex={"module": module, "entry_point": "vs_main"},
            fragment={"module": module, "entry_point": "fs_main",
                      "targets": [{"format": self.format}]},
            primitive={"topology": "triangle-list"}, label="rfw:blit")

    def _rebuild(self) -> None:
        from .backends.wgpu_backend import Executor

        built = build(self.cfg)
        plan = compile(built.graph)
        old = self.executor
        self.executor = Executor(self.device, plan, built.passes, built.slots,
                                 self.gpu_scene, present=plan.outputs[:1])
        if old is not None:
            self.executor.shaders = old.shaders  # keep compiled pipelines across toggles
            old.destroy()
        self.gpu_scene.camera = self.camera
        self.gpu_scene.set_viewport(self.cfg.size)
        self.output = plan.outputs[0]
        self.say(f"graph: {' -> '.join(plan.order)}"
                 + (f" (off: {', '.join(plan.disabled)})" if plan.disabled else ""))

    def say(self, text: str) -> None:
        self.log.append(text)
        print(text, flush=True)

    # input --------------------------------------------------------------------------------
    def key(self, key: str, shift: bool = False) -> None:
        """Apply one key press (also used by ``--script`` and tests)."""
        passes = [p.name for p in self.cfg.passes]
        if key.isdigit() and 1 <= int(key) <= len(passes):
            name = passes[int(key) - 1]
            entry = self.cfg.entry(name)
            self._apply([f"{name}.enabled={'false' if entry.enabled else 'true'}"])
        elif key.lower() == "v" and self.cfg.variants:
            groups = list(self.cfg.variants)
            group = groups[(1 if shift and len(groups) > 1 else 0)]
            options = [k for k in self.cfg.variants[group] if k != "default"]
            now = self.cfg.chosen.get(group, options[0])
            self._apply([f"{group}={options[(options.index(now) + 1) % len(options)]}"])
        elif key.lower() == "r":
            self.executor.shaders.programs.clear()
            self.say("shaders reloaded")
        elif key.lower() == "p":
            self.report()
        elif key.lower() in "wasdqe":
            self._move(key.lower())

    def _apply(self, sets: list[str]) -> None:
        try:
            cfg = apply_overrides(self.cfg, sets)
            self.cfg = cfg
            self._rebuild()
        except GraphError as e:  # a toggle that breaks the graph is refused, not fatal
            self.say(f"refused {', '.join(sets)}: {e}")

    def _move(self, k: str) -> None:
        eye, at = np.array(self.camera.position), np.array(self.camera.target)
        fwd = (at - eye) / np.linalg.norm(at - eye)
        right = np.cross(fwd, self.camera.up)
        right /= np.linalg.norm(right)
        step = 0.05 * np.linalg.norm(at - eye)
        d = {"w": fwd, "s": -fwd, "d": right, "a": -right, "e": np.array(self.camera.up),
             "q": -np.array(self.camera.up)}[k] * step
        self._set_camera(eye + d, at + d)

    def _orbit(self, dx: float, dy: float) -> None:
        eye, at = np.array(self.camera.position), np.array(self.camera.target)
        off = eye - at
        r = np.linalg.norm(off)
        yaw = math.atan2(off[0], off[2]) - dx * 0.01
        pitch = max(-1.5, min(1.5, math.asin(off[1] / r) + dy * 0.01))
        off = r * np.array([math.cos(pitch) * math.sin(yaw), math.sin(pitch),
                            math.cos(pitch) * math.cos(yaw)])
        self._set_camera(at + off, at)

    def _zoom(self, amount: float) -> None:
        eye, at = np.array(self.camera.position), np.array(self.camera.target)
        self._set_camera(at + (eye - at) * (1.0 + amount), at)

    def _set_camera(self, eye: np.ndarray, at: np.ndarray) -> None:
        self.camera = replace(self.camera, position=tuple(eye), target=tuple(at))
        self.gpu_scene.camera = self.camera
        self.gpu_scene.set_viewport(self.cfg.size)

    def _on_event(self, event: dict) -> None:
        kind = event["event_type"]
        if kind == "key_down":
            self.key(str(event.get("key", "")), "Shift" in event.get("modifiers", ()))
        elif kind == "pointer_down":
            self._drag = (event["x"], event["y"])
        elif kind == "pointer_move" and event.get("buttons"):
            if self._drag is not None:
                self._orbit(event["x"] - self._drag[0], event["y"] - self._drag[1])
            self._drag = (event["x"], event["y"])
        elif kind == "wheel":
            self._zoom(0.001 * event.get("dy", 0.0))

    # drawing ------------------------------------------------------------------------------
    def draw(self) -> None:
        if self.script:
            self.key(self.script.pop(0))
        try:
            self.executor.frame()
        except GraphError as e:  # e.g. a shader edited into an error: keep the window up
            self.say(f"frame skipped: {e}")
            return
        target = self.context.get_current_texture()
        dev = self.device.device
        src = self.executor.view(self.output)
        bg = dev.create_bind_group(layout=self._blit.get_bind_group_layout(0),
                                   entries=[{"binding": 0, "resource": src}])
        enc = dev.create_command_encoder(label="rfw:present")
        rp = enc.begin_render_pass(color_attachments=[{
            "view": target.create_view(), "load_op": "clear", "store_op": "store",
            "clear_value": (0, 0, 0, 1)}])
        rp.set_pipeline(self._blit)
        rp.set_bind_group(0, bg)
        rp.draw(3)
        rp.end()
        dev.queue.submit([enc.finish()])
        self.frame_count += 1
        if self.report_every and self.frame_count % self.report_every == 0:
            self.report()
        if self.frames_left is not None:
            self.frames_left -= 1
            if self.frames_left <= 0:
                self.canvas.close()

    def report(self) -> None:
        self.executor.drain()  # frames in flight append their timings once done
        parts = []
        for name, t in self.executor.timings.items():
            recent = t.gpu_ms[-30:] or t.cpu_ms[-30:]
            parts.append(f"{name} {statistics.median(recent):.2f}")
        line = f"frame {self.frame_count} gpu ms: " + ", ".join(parts)
        self.canvas.set_title(f"rfw: {self.cfg.name} | {line}")
        self.say(line)

    def run(self) -> None:
        self.canvas.request_draw(self.draw)
        self.loop.run()
        self.close()

    def close(self) -> None:
        if self.executor is not None:
            self.executor.destroy()
            self.executor = None
        self.gpu_scene.destroy()


def view(config: Path, sets: list[str], *, scene: str | None = None,
         frames: int | None = None, script: list[str] = ()) -> Viewer:
    from .config import load_config

    cfg = load_config(config)
    if scene:
        sets = [*sets, f"scene={scene}"]
    cfg = apply_overrides(cfg, sets)
    compile(build(cfg).graph)  # config and scene errors first, with or without a display
    loaded = load_scene_for(cfg)
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        # glfw aborts the process without a display: say so instead
        raise RfwError("no display for a window (set DISPLAY, or run under xvfb-run -a); "
                       "'rfw run' renders headless", element="rfw view")
    v = Viewer(cfg, scene=loaded, frames=frames, script=script)
    start = time.perf_counter()
    v.run()
    v.say(f"closed after {v.frame_count} frames in {time.perf_counter() - start:.1f} s")
    return v
