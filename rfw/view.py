"""``rfw view``: a live window (glfw through rendercanvas) with camera, toggles and timings.

Mouse drag orbits, wheel zooms, W/A/S/D/Q/E move. Keys 1-9 toggle the config's passes in
order, V cycles the options of the selected variant group and Shift+V selects the next group
(every group is reachable, and listed on screen), R reloads shaders, P prints the per-pass
table, H hides or shows the overlay (:mod:`rfw.overlay`), C saves the presented pixels to the
``--screenshot`` file. Shaders are also reloaded whenever their source changes: the pipeline
cache is keyed by the preprocessed source's hash.

The frame runs on any backend, as ``rfw run`` does (``--backend``; default: the one the
config's passes are pinned to, else wgpu; pinned passes mix in through bridges): the window's
own wgpu device copies a wgpu output on the GPU, another backend's output (vk: meshlets with
GPU culling, ray-traced shadows) is read back each frame and uploaded, so what the window
shows is what ``rfw run --backend`` writes on either. The overlay then shows that backend's
culling counters and memory.

The window shows the graph output's bytes as they are: the swapchain is configured with a
non-sRGB format (the output is display-encoded already; an ``*-srgb`` swapchain would encode
it a second time). A change (key or mouse) is transactional: the new config is built,
compiled and given an executor before it replaces the current one; a refused change leaves
everything as it was and says why in one line. A frame that fails (a shader edited into an
error) says so once, not every frame, and once more when frames render again.
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
import wgpu

from .backend import Devices, get_backend
from .camera_path import path_for
from .config import Config, apply_overrides, build, resolve_auto
from .errors import RfwError
from .frame import (
    camera_for,
    load_scene_for,
    pinned_elsewhere,
    prepare,
    start,
)
from .graph import compile
from .options import DEFAULT, RunOptions
from .overlay import Overlay
from .render import backend_for

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


STATS_EVERY = 15  # frames between reads of the culling counters and memory (they wait)

# said once at start: a config's camera.path drives rfw run and rfw bench, not the window
PATH_NOTE = "camera.path is not followed by rfw view: it shows the path's first camera"


class Viewer:
    """Owns the window, the device, the scene and the executor of the current config."""

    def __init__(self, cfg: Config, *, scene: Any = None, script: list[str] = (),
                 frames: int | None = None, report_every: int = 60, canvas: Any = None,
                 overlay: bool = True, screenshot: Path | None = None,
                 backend: str | None = None, options: RunOptions = DEFAULT):
        from rendercanvas.glfw import RenderCanvas, loop

        from .backends.wgpu import Device

        self.cfg = cfg
        self.loop = loop
        self.backend = backend or backend_for(cfg)
        # a bad config, backend or scene fails here, before a window opens
        get_backend(self.backend, file=cfg.source)
        compile(build(cfg).graph)
        self.scene = load_scene_for(cfg, scene)
        self.camera = camera_for(cfg, self.scene)
        path = path_for(cfg, self.camera)
        if path is not None:  # the window's camera is the user's to move, not the path's
            self.camera = path.at(0.0)
            print(PATH_NOTE, flush=True)
        self.canvas = canvas or RenderCanvas(size=cfg.size, title=f"rfw: {cfg.name}",
                                             update_mode="continuous")
        # the window's device: it presents, and runs the wgpu part of a frame; another
        # backend's device is made on first use (with its validation layer: --validate)
        self.device = Device(gpu=options.gpu)
        self.options = options  # validation, frames in flight, vk's switches (rfw.options)
        self.devices = Devices((self.device,), options=options)
        self.validation = options.validation
        self.uploads: dict[str, Any] = {}  # backend -> the scene uploaded there, kept
        self.context = self.canvas.get_wgpu_context()
        self.format = present_format(self.context.get_preferred_format(self.device.adapter))
        # COPY_SRC: the presented texture can be read back (C, --screenshot, the tests)
        try:
            self.context.configure(device=self.device.device, format=self.format,
                                   usage=wgpu.TextureUsage.RENDER_ATTACHMENT |
                                   wgpu.TextureUsage.COPY_SRC)
        except ValueError as e:  # a format this surface does not offer
            self.canvas.close()
            raise RfwError(str(e).splitlines()[0], element="RFW_VIEW_FORMAT") from None
        self.script = list(script)
        self.frames_left = frames
        self.report_every = report_every
        self.screenshot = screenshot
        self.frame_count = 0  # frames drawn
        self.frame: Any = None  # the rfw.frame.Frame of the current config
        self.techniques: dict[str, str] = {}  # what auto variants chose on this device
        self.stats: dict[str, dict[str, Any]] = {}  # backend -> its collect(), refreshed
        self.log: list[str] = []
        self.status = ""  # the last refusal or error, shown in the overlay
        self.group = 0  # the variant group V cycles
        self.captured: np.ndarray | None = None  # the last presented pixels read back (RGBA)
        self._capture_next = False
        self._error: str | None = None  # the frame error said last (said once)
        self._last_draw: float | None = None
        self._later: list[tuple[Any, tuple]] = []
        self._tried: dict[str, str] = {}  # variant group -> the option V tried last
        self._shown: Any = None  # the texture the window blits: the output's copy
        self._shown_group: Any = None  # the blit's bind group of that texture
        self._blit = self._blit_pipeline()
        try:
            self._rebuild(cfg)
        except BaseException:
            self.canvas.close()
            self.close()
            raise
        self.overlay = Overlay(self, self.canvas, self.device.device, self.format) \
            if overlay else None
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

    def _rebuild(self, cfg: Config) -> None:
        """Make ``cfg`` current: everything that can fail happens before anything changes."""
        run = get_backend(self.backend, file=cfg.source)
        techniques: dict[str, str] = {}
        resolved = cfg
        if run.auto_variants:  # auto variants resolve for the device, as rfw run does
            resolved, techniques = resolve_auto(cfg, run.caps(self.devices.get(run)))
        mix = pinned_elsewhere(resolved, self.backend)
        built = build(resolved, self.scene)
        # frames in flight: the run's, else this config's (as rfw run does)
        options = self.options.replace(
            frames_in_flight=self.options.in_flight(cfg.frames_in_flight))
        frame_plan, sides = prepare(built, self.backend, self.devices, options=options,
                                    mix=mix)
        for name, side in sides.items():  # the scene goes up once per backend, not per change
            if name not in self.uploads:
                self.uploads[name] = side.backend.scene(side.device, self.scene, self.camera,
                                                        cfg.size)
        frame = start(frame_plan, sides, options=options, uploads=self.uploads)
        output = frame_plan.plan.outputs[0]
        old = self.frame
        if old is not None:
            keep = old.executors.get("wgpu")
            new = frame.executors.get("wgpu")
            if keep is not None and new is not None:
                new.shaders = keep.shaders  # keep compiled pipelines across toggles
            old.destroy()
        self.frame, self.cfg, self.techniques = frame, cfg, techniques
        self.group = min(self.group, max(0, len(cfg.variants) - 1))
        for upload in self.uploads.values():
            upload.camera = self.camera
            upload.set_viewport(self.cfg.size)
        self.output = output
        self.output_format = frame_plan.plan.resource(output).format
        self.stats = {}
        self._warm = False  # the first frame compiles pipelines: its times are dropped
        shown = self._shown_texture()
        if shown is not self._shown or self._shown_group is None:  # made once per texture
            self._shown_group = self.device.device.create_bind_group(
                layout=self._blit.get_bind_group_layout(0),
                entries=[{"binding": 0, "resource": shown.create_view()}])
        self._shown = shown
        plan = frame_plan.plan
        self.say(f"graph: {' -> '.join(plan.order)}"
                 + (f" (off: {', '.join(plan.disabled)})" if plan.disabled else "")
                 + ("" if self.backend == "wgpu" and not mix else
                    f" on {'+'.join(frame.executors)}"))
        if techniques:
            self.say("techniques: " + ", ".join(f"{k}={v}" for k, v in techniques.items()))

    @property
    def executors(self) -> dict[str, Any]:
        """The current frame's executors by backend."""
        return self.frame.executors

    @property
    def plan(self) -> Any:
        """The current config's compiled plan (every backend's passes, bridges included)."""
        return self.frame.plan

    def timings(self) -> dict[str, Any]:
        """Per pass (every backend's), its timings; bridges (host copies) included."""
        out: dict[str, Any] = {}
        for ex in self.frame.executors.values():
            out.update(ex.timings)
        out.update(self.frame.bridge_timings)
        return out

    def backend_of(self, name: str) -> str | None:
        """The backend pass ``name`` runs on now (None: off or culled)."""
        return self.frame.frame_plan.backend_of(name)

    def _shown_texture(self) -> Any:
        """The texture the window shows: a copy of the output on the window's device."""
        from .backends.wgpu.resources import wgpu_format

        r = self.frame.plan.resource(self.output)
        old = self._shown
        if old is not None and tuple(old.size[:2]) == (r.width, r.height) and \
                str(old.format) == wgpu_format(r.format):
            return old
        if old is not None:
            old.destroy()
        return self.device.device.create_texture(
            size=(r.width, r.height, 1), format=wgpu_format(r.format),
            usage=wgpu.TextureUsage.COPY_DST | wgpu.TextureUsage.TEXTURE_BINDING,
            label="rfw:shown")

    def say(self, text: str) -> None:
        self.log.append(text)
        print(text, flush=True)

    # input --------------------------------------------------------------------------------
    def key(self, key: str, shift: bool = False) -> None:
        """Apply one key press (also used by ``--script`` and tests)."""
        passes = [p.name for p in self.cfg.passes]
        if key.isdigit() and 1 <= int(key) <= len(passes):
            name = passes[int(key) - 1]
            self.set_pass(name, not self.cfg.entry(name).enabled)
        elif key.lower() == "v" and self.cfg.variants:
            groups = list(self.cfg.variants)
            if shift or key == "V":  # the next group: every group is reachable
                self.group = (self.group + 1) % len(groups)
                self.say(f"variant group: {self.variants_line()}")
                return
            group = groups[self.group]
            options = [k for k in self.cfg.variants[group] if k != "default"]
            # after a refused option the next V tries the one after it, not it again
            start = self._tried.get(group, self.chosen(group))
            option = options[(options.index(start) + 1) % len(options)]
            self._tried[group] = option
            if self.choose(group, option):
                self._tried.pop(group)
        elif key.lower() == "r":
            self.reload()
        elif key.lower() == "p":
            self.report()
        elif key.lower() == "h" and self.overlay is not None:
            self.overlay.visible = not self.overlay.visible
        elif key.lower() == "c":
            if self.screenshot is None:
                self.say("C saves a screenshot where --screenshot says: none given")
            else:
                self._capture_next = True
        elif key.lower() in "wasdqe":
            self._move(key.lower())

    def reload(self) -> None:
        """R: shaders read again. wgpu compiles on the next frame (a broken shader skips
        frames until fixed); another backend compiles when its executor is made, so the
        frame is built again, transactionally (a broken shader is refused, and the shaders
        that worked keep running)."""
        wgpu_ex = self.frame.executors.get("wgpu")
        if wgpu_ex is not None:
            wgpu_ex.shaders.programs.clear()
        if set(self.frame.executors) - {"wgpu"} and not self._apply([]):
            return  # refused: the shaders that worked keep running
        self.say("shaders reloaded")

    def later(self, action: Any, *args: Any) -> None:
        """Run ``action(*args)`` once the frame being drawn is submitted (the overlay's
        clicks: a change replaces the executor whose images the frame still reads)."""
        self._later.append((action, args))

    def set_pass(self, name: str, enabled: bool) -> bool:
        """Switch pass ``name`` on or off (keys 1-9, the overlay's checkboxes)."""
        return self._apply([f"{name}.enabled={'true' if enabled else 'false'}"])

    def chosen(self, group: str) -> str:
        options = [k for k in self.cfg.variants[group] if k != "default"]
        return self.cfg.chosen.get(group, options[0])

    def choose(self, group: str, option: str) -> bool:
        """Pick ``option`` of variant group ``group`` (V, the overlay's buttons)."""
        return self._apply([f"{group}={option}"])

    def variants_line(self) -> str:
        """Every variant group with its option in force; ``>`` marks the one V cycles."""
        return ", ".join(f"{'>' if i == self.group else ''}{g}={self.chosen(g)}"
                         for i, g in enumerate(self.cfg.variants))

    def culling(self) -> dict[str, Any]:
        """The GPU culling counters of the last frame read (meshlet passes on vk; {} where
        no pass counts), refreshed every ``STATS_EVERY`` frames."""
        for stats in self.stats.values():
            if stats.get("culling"):
                return dict(stats["culling"])
        return {}

    def memory(self) -> dict[str, dict[str, Any]]:
        """Per backend of the frame, the memory its executor reports (vk: transients
        allocated, allocations), refreshed with the culling counters."""
        return {name: stats["memory"] for name, stats in self.stats.items()
                if stats.get("memory")}

    def _collect(self) -> None:
        # each backend's own numbers (what timings.json's culling and memory hold); reading
        # the counters back waits for the frame, so not every frame
        self.frame.drain()
        self.stats = {name: self.frame.backends[name].collect(ex)
                      for name, ex in self.frame.executors.items()}

    def _apply(self, sets: list[str]) -> bool:
        """All or nothing: a change that breaks the config or graph leaves the current one."""
        try:
            self._rebuild(apply_overrides(self.cfg, sets))
        except RfwError as e:  # a toggle that breaks the graph is refused, not fatal
            self.status = f"refused {', '.join(sets) or 'reload'}: {e}"
            self.say(self.status)
            return False
        self.status = ""
        if self.cfg.variants:
            self.say(f"variants: {self.variants_line()}")
        return True

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
        self.frame.set_camera(self.camera)  # the next frame's: frames in flight keep theirs

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
            k = self.script.pop(0)
            self.key(k, shift=k == "V")
        now = time.perf_counter()
        if self._last_draw is not None and self.overlay is not None:
            self.overlay.frame_ms.append((now - self._last_draw) * 1e3)
        self._last_draw = now
        last = self.frames_left is not None and self.frames_left <= 1
        try:
            self.frame.step(last=False)
            self._fill_shown()
            ok = True
        except RfwError as e:  # e.g. a shader edited into an error: keep the window up
            self._failed(f"frame skipped: {e}")
            ok = False
        if ok and self._error is not None:
            self._error, self.status = None, ""
            self.say("frames render again")
        # a failed frame shows the last image, and the overlay with the error and its
        # checkboxes (a click can switch the broken pass off)
        self._present(capture=ok and ((last and self.screenshot is not None)
                                      or self._capture_next))
        while self._later:
            action, args = self._later.pop(0)
            action(*args)
        if ok:
            if not self._warm:  # as rfw run's warm-up: compile times are no frame's cost
                self.frame.clear_timings()
                self._warm = True
            self.frame_count += 1
            # from the second frame on: the first has no earlier depth for occlusion tests
            if self.frame_count % STATS_EVERY == 2 or last:
                self._collect()
            if self.report_every and self.frame_count % self.report_every == 0:
                self.report()
        if self.frames_left is not None:  # failed frames count: --frames always ends
            self.frames_left -= 1
            if self.frames_left <= 0:
                self.canvas.close()

    def _failed(self, line: str) -> None:
        # said once: the same error on every frame would bury everything else
        if line != self._error:
            self._error = self.status = line
            self.say(line)

    def _present(self, *, capture: bool) -> None:
        target = self.context.get_current_texture()
        dev = self.device.device
        enc = dev.create_command_encoder(label="rfw:present")
        rp = enc.begin_render_pass(color_attachments=[{
            "view": target.create_view(), "load_op": "clear", "store_op": "store",
            "clear_value": (0, 0, 0, 1)}])
        rp.set_pipeline(self._blit)
        rp.set_bind_group(0, self._shown_group)
        rp.draw(3)
        if self.overlay is not None and self.overlay.visible:
            self.overlay.draw(rp, (target.width, target.height))
        rp.end()
        dev.queue.submit([enc.finish()])
        if capture:
            self._capture_next = False
            self.captured = read_target(dev, target, self.format)
            if self.screenshot is not None:
                save_png(self.screenshot, self.captured)
                self.say(f"wrote {self.screenshot}")

    def _fill_shown(self) -> None:
        """Copy the frame's output into the shown texture: on the GPU where the window's
        device rendered it, else read back (after the frame) and uploaded."""
        dev = self.device.device
        owner = self.frame.frame_plan.owner[self.output]
        size = (self._shown.width, self._shown.height, 1)
        if owner == "wgpu":
            enc = dev.create_command_encoder(label="rfw:shown")
            enc.copy_texture_to_texture(
                {"texture": self.frame.executors["wgpu"].texture(self.output)},
                {"texture": self._shown}, size)
            dev.queue.submit([enc.finish()])
            return
        data = np.ascontiguousarray(self.frame.read(self.output))
        dev.queue.write_texture({"texture": self._shown}, data,
                                {"bytes_per_row": data.nbytes // size[1]}, size)

    def report(self) -> None:
        self.frame.drain()  # frames in flight append their timings once done
        parts = []
        for name, t in self.timings().items():
            recent = getattr(t, "gpu_ms", [])[-30:] or t.cpu_ms[-30:]
            if not recent:  # no frame of this graph has finished yet
                continue
            parts.append(f"{name} {statistics.median(recent):.2f}")
        line = f"frame {self.frame_count} gpu ms: " + (", ".join(parts) or
                                                       "none yet (no timed frame is done)")
        self.canvas.set_title(f"rfw: {self.cfg.name} | {line}")
        self.say(line)

    def run(self) -> None:
        self.canvas.request_draw(self.draw)
        self.loop.run()
        self.close()

    def close(self) -> None:
        if getattr(self, "overlay", None) is not None:
            self.overlay.close()  # what it showed last stays readable
        if self.frame is not None:
            self.frame.destroy()
            self.frame = None
        for upload in self.uploads.values():
            upload.destroy()
        self.uploads = {}
        if self._shown is not None:
            self._shown.destroy()
            self._shown = None
        self.devices.close()  # validation's leak reports arrive here
        if self.validation:
            messages = [m for name, dev in self.devices.devices.items()
                        for m in getattr(dev, "messages", ())]
            self.say(f"validation: {len(messages)} messages")
            for m in messages[:5]:
                self.say(f"  {m.text}")


def present_format(preferred: str) -> str:
    """The swapchain format: the preferred one without ``-srgb`` (the graph output is
    display-encoded already). ``RFW_VIEW_FORMAT`` names another (the tests' negative
    control shows an ``*-srgb`` one double-encodes)."""
    from . import env

    chosen = env.get("RFW_VIEW_FORMAT") or preferred.removesuffix("-srgb")
    if chosen not in env.VIEW_FORMATS:  # the adapter's preferred one too
        raise RfwError(f"'{chosen}' is no window format (bgra8unorm, rgba8unorm, or either "
                       "with -srgb)", element="RFW_VIEW_FORMAT")
    return chosen


def read_target(dev: Any, texture: Any, fmt: str) -> np.ndarray:
    """The pixels of a presented (not yet shown) texture as RGBA bytes, rows top first."""
    w, h = texture.width, texture.height
    row = (w * 4 + 255) // 256 * 256
    data = dev.queue.read_texture({"texture": texture, "origin": (0, 0, 0)},
                                  {"offset": 0, "bytes_per_row": row}, (w, h, 1))
    a = np.frombuffer(data, np.uint8).reshape(h, row)[:, :w * 4].reshape(h, w, 4)
    return np.ascontiguousarray(a[..., [2, 1, 0, 3]] if fmt.startswith("bgra") else a)


def save_png(path: Path, rgba: np.ndarray) -> None:
    from .fileio import atomic_write, png_bytes

    data = png_bytes(rgba, "rgba8unorm")  # RGBA bytes: written as they are
    atomic_write(path, lambda f: f.write(data))


def check_screenshot(path: Path | None) -> None:
    """A screenshot path is checked before a window opens."""
    if path is None:
        return
    if path.suffix.lower() != ".png":
        raise RfwError("a screenshot is written as PNG: give a .png name", file=str(path),
                       element="--screenshot")
    if not path.parent.is_dir():
        raise RfwError(f"no folder '{path.parent}' to write the screenshot into",
                       file=str(path), element="--screenshot")


def view(config: Path, sets: list[str], *, scene: str | None = None,
         frames: int | None = None, script: list[str] = (), overlay: bool = True,
         screenshot: Path | None = None, backend: str | None = None,
         options: RunOptions = DEFAULT, fetch: bool = False) -> Viewer:
    from .config import load_config
    from .scene.names import config_scene

    check_screenshot(screenshot)
    present_format("bgra8unorm")  # a bad RFW_VIEW_FORMAT fails before a window opens
    cfg = load_config(config)
    if scene is not None:  # "" too: config_scene names --scene for it
        sets = [*sets, f"scene={scene}"]
    cfg = apply_overrides(cfg, sets)
    # --scene dragon or scene = "dragon": the cached GLB (fetched first with --fetch), as in
    # rfw run
    cfg = config_scene(cfg, fetch=fetch, flag=scene is not None)
    compile(build(cfg).graph)  # config and scene errors first, with or without a display
    backend = backend or backend_for(cfg)
    get_backend(backend, file=cfg.source)  # an unknown name: one line naming the installed
    if options.validation and backend == "wgpu" and not pinned_elsewhere(cfg, backend):
        raise RfwError("--validate needs a Vulkan part of the frame: --backend vk, or a "
                       "pass pinned to vk", file=cfg.source, element="--validate")
    loaded = load_scene_for(cfg)
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        # glfw aborts the process without a display: say so instead
        raise RfwError("no display for a window (set DISPLAY, or run under xvfb-run -a); "
                       "'rfw run' renders headless", element="rfw view")
    v = Viewer(cfg, scene=loaded, frames=frames, script=script, overlay=overlay,
               screenshot=screenshot, backend=backend, options=options)
    start = time.perf_counter()
    v.run()
    v.say(f"closed after {v.frame_count} frames in {time.perf_counter() - start:.1f} s")
    if screenshot is not None and frames is not None and v._error is not None:
        # the last frame failed: no screenshot of it (one C wrote earlier is older)
        old = " (the file there is from an earlier frame)" if screenshot.exists() else ""
        raise RfwError(f"no screenshot of the last frame: {v._error}{old}",
                       file=str(screenshot), element="--screenshot")
    return v
