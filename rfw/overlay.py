"""``rfw view``'s on-screen overlay: Dear ImGui (imgui-bundle) drawn with wgpu-py's imgui
backend into the window's own render pass, after the graph's image.

It shows per-pass GPU and CPU ms (medians of the last frames) with the backend each pass
ran on where the frame mixes them, the plan's memory (transient bytes after aliasing, before
aliasing, the textures the wgpu executor holds, what the vk executor allocated), the meshlet
passes' GPU culling counters (vk), a frame-time graph, and the variant groups; a checkbox per
pass and a button per variant option change the config through the viewer, which refuses a
change that breaks the graph (the overlay shows the reason). The overlay only reads the
viewer's state and calls :meth:`rfw.view.Viewer.set_pass` / :meth:`~rfw.view.Viewer.choose`.
"""

from __future__ import annotations

import statistics
from collections import deque
from typing import Any

import numpy as np

HISTORY = 120  # frames the frame-time graph shows
RECENT = 30  # frames the per-pass medians are taken over


def _mib(n: float) -> str:
    return f"{n / (1 << 20):.2f} MiB"


def median_ms(values: list[float]) -> float | None:
    recent = values[-RECENT:]
    return statistics.median(recent) if recent else None


def texture_bytes(executor: Any) -> int:
    """Bytes of the textures ``executor`` holds (each mip, layer and sample counted, whole
    blocks of compressed formats): :func:`rfw.graph.formats.image_bytes` of each."""
    from .graph.formats import image_bytes

    total = 0
    for tex in getattr(executor, "_textures", {}).values():
        w, h, layers = tex.size
        try:
            total += image_bytes(str(tex.format), w, h, mips=tex.mip_level_count,
                                 layers=layers, samples=tex.sample_count)
        except ValueError:  # a format the table does not know: counted at 4 bytes a texel
            total += image_bytes("rgba8unorm", w, h, mips=tex.mip_level_count,
                                 layers=layers, samples=tex.sample_count)
    return total


class Overlay:
    """ImGui over the viewer's window; ``draw(render_pass)`` records it into that pass."""

    def __init__(self, viewer: Any, canvas: Any, device: Any, target_format: str):
        from imgui_bundle import imgui
        from wgpu.utils.imgui.imgui_backend import ImguiWgpuBackend

        self.imgui = imgui
        self.viewer = viewer
        self.canvas = canvas
        self.context = imgui.create_context()
        imgui.set_current_context(self.context)
        self.backend = ImguiWgpuBackend(device, target_format)
        self.io = self.backend.io
        self.frame_ms: deque[float] = deque(maxlen=HISTORY)
        self.visible = True
        self._held: tuple[Any, int] = (None, 0)  # (wgpu executor, bytes of its textures)
        # what the last frame showed: its text lines, and where each control lies (for
        # tests and scripts, which click through the window's own events)
        self.lines: list[str] = []
        self.rects: dict[str, tuple[float, float, float, float]] = {}
        # the overlay takes mouse events over its window before the viewer's camera does
        canvas.add_event_handler(self._on_pointer, "pointer_move", "pointer_down",
                                 "pointer_up", order=-99)
        canvas.add_event_handler(self._on_wheel, "wheel", order=-99)

    def close(self) -> None:
        if self.context is not None:
            self.imgui.destroy_context(self.context)
            self.context = None

    # input --------------------------------------------------------------------------------
    def _on_pointer(self, event: dict) -> None:
        self.io.add_mouse_pos_event(event["x"], event["y"])
        if event["event_type"] != "pointer_move":
            self.io.add_mouse_button_event(max(0, event.get("button", 1) - 1),
                                           event["event_type"] == "pointer_down")
        if self.visible and self.io.want_capture_mouse:
            event["stop_propagation"] = True

    def _on_wheel(self, event: dict) -> None:
        self.io.add_mouse_wheel_event(event.get("dx", 0.0) / 100, -event.get("dy", 0.0) / 100)
        if self.visible and self.io.want_capture_mouse:
            event["stop_propagation"] = True

    # drawing ------------------------------------------------------------------------------
    def draw(self, render_pass: Any, size: tuple[int, int]) -> None:
        imgui = self.imgui
        imgui.set_current_context(self.context)
        self.io.display_size = (float(size[0]), float(size[1]))
        self.io.display_framebuffer_scale = (1.0, 1.0)
        self.lines, self.rects = [], {}
        imgui.new_frame()
        try:
            self._gui()
        finally:
            imgui.render()
        self.backend.render(imgui.get_draw_data(), render_pass)

    def _text(self, line: str) -> None:
        self.imgui.text(line)
        self.lines.append(line)

    def _rect(self, name: str) -> None:
        lo, hi = self.imgui.get_item_rect_min(), self.imgui.get_item_rect_max()
        self.rects[name] = (lo.x, lo.y, hi.x, hi.y)

    def _gui(self) -> None:
        imgui, v = self.imgui, self.viewer
        imgui.set_next_window_pos((4, 4), imgui.Cond_.first_use_ever)
        # never larger than the window: what does not fit scrolls (a small window or a
        # long list of counters and variants is not cut off)
        w, h = self.io.display_size
        imgui.set_next_window_size_constraints((0.0, 0.0), (max(64.0, w - 8.0),
                                                            max(64.0, h - 8.0)))
        imgui.set_next_window_bg_alpha(0.75)
        imgui.begin("rfw", None, imgui.WindowFlags_.always_auto_resize)
        self._text(f"{v.cfg.name}  {v.cfg.size[0]}x{v.cfg.size[1]}  frame {v.frame_count}")
        self._timings()
        self._bridges()
        self._frame_graph()
        self._memory()
        self._variants()
        if v.status:
            imgui.text_wrapped(v.status)
            self.lines.append(v.status)
        pos, size = imgui.get_window_pos(), imgui.get_window_size()
        self.rects["window"] = (pos.x, pos.y, pos.x + size.x, pos.y + size.y)
        imgui.end()

    def _timings(self) -> None:
        """A row per pass of the config: its checkbox (key 1-9) and its GPU and CPU ms."""
        imgui, v = self.imgui, self.viewer
        if not imgui.begin_table("passes", 3, imgui.TableFlags_.borders_inner_v):
            return
        for head in ("pass (keys 1-9)", "GPU ms", "CPU ms"):
            imgui.table_setup_column(head)
        imgui.table_headers_row()
        timings = v.timings()
        mixed = len(v.executors) > 1
        for i, entry in enumerate(v.cfg.passes):
            imgui.table_next_row()
            imgui.table_next_column()
            side = v.backend_of(entry.name)
            label = f"{i + 1} {entry.name}" + (f" [{side}]" if mixed and side else "")
            changed, on = imgui.checkbox(f"{label}##pass", entry.enabled)
            self._rect(f"pass:{entry.name}")
            if changed:  # applied after this frame's submit: it may replace the executor
                v.later(v.set_pass, entry.name, on)
            t = timings.get(entry.name)
            if t is None:  # disabled, or culled: nothing reads it
                self.lines.append(f"{entry.name} off")
                continue
            gpu, cpu = median_ms(t.gpu_ms), median_ms(t.cpu_ms)
            imgui.table_next_column()
            imgui.text("-" if gpu is None else f"{gpu:.3f}")
            imgui.table_next_column()
            imgui.text("-" if cpu is None else f"{cpu:.3f}")
            self.lines.append(f"{entry.name} gpu {'-' if gpu is None else f'{gpu:.3f}'} "
                              f"cpu {'-' if cpu is None else f'{cpu:.3f}'}"
                              + (f" on {side}" if mixed else ""))
        imgui.end_table()

    def _bridges(self) -> None:
        """A mixed frame's host copies between backends: wall ms each, and bytes."""
        for name, t in self.viewer.frame.bridge_timings.items():
            ms = median_ms(t.cpu_ms)
            self._text(f"{name}: host copy {'-' if ms is None else f'{ms:.3f}'} ms, "
                       f"{_mib(t.bytes)}")

    def _frame_graph(self) -> None:
        imgui = self.imgui
        values = np.array(self.frame_ms, np.float32)
        if len(values) < 2:
            return
        top = float(values.max()) * 1.1
        text = f"frame {values[-1]:.1f} ms (max {values.max():.1f})"
        imgui.plot_lines("##frame", values, overlay_text=text, scale_min=0.0, scale_max=top,
                         graph_size=(260, 40))
        self._rect("frame_graph")
        self.lines.append(f"graph: {text}")

    def _memory(self) -> None:
        v = self.viewer
        plan = v.plan
        self._text(f"memory: transients {_mib(plan.transient_bytes)} aliased, "
                   f"{_mib(plan.unaliased_bytes)} unaliased")
        wgpu_ex = v.executors.get("wgpu")
        if wgpu_ex is not None:
            if self._held[0] is not wgpu_ex:  # an executor makes its textures once
                self._held = (wgpu_ex, texture_bytes(wgpu_ex))
            self._text(f"        textures held {_mib(self._held[1])}")
        for name, mem in v.memory().items():
            if "transient_allocated_bytes" in mem:
                self._text(f"        {name}: transients allocated "
                           f"{_mib(mem['transient_allocated_bytes'])} in "
                           f"{mem.get('allocations', 0)} allocation(s)")
        culling = v.culling()
        shown = {k: val for k, val in culling.items() if val is not None}
        if not shown:
            self._text("culling: no GPU culling counters in this frame")
            return
        # the counters in lines of three, meshlets first
        items = [f"{k} {val:,}" for k, val in shown.items()]
        self._text("culling: " + ", ".join(items[:3]))
        for k in range(3, len(items), 3):
            self._text("         " + ", ".join(items[k:k + 3]))

    def _variants(self) -> None:
        imgui, v = self.imgui, self.viewer
        if not v.cfg.variants:
            return
        imgui.separator_text("variants (V cycles, Shift+V next group)")
        if v.techniques:  # auto options as this device resolved them
            self._text("auto: " + ", ".join(f"{k}={t}" for k, t in v.techniques.items()))
        for gi, (group, options) in enumerate(v.cfg.variants.items()):
            mark = ">" if gi == v.group else " "
            imgui.text(f"{mark} {group}:")
            self.lines.append(f"{mark} {group}: " + " ".join(
                f"[{o}]" if o == v.chosen(group) else o for o in options if o != "default"))
            for option in (o for o in options if o != "default"):
                imgui.same_line()
                chosen = v.chosen(group) == option
                clicked = imgui.radio_button(f"{option}##{group}", chosen)
                self._rect(f"variant:{group}={option}")
                if clicked and not chosen:
                    v.group = gi
                    v.later(v.choose, group, option)
