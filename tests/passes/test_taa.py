"""TAA (configs/deferred_ssao_shadows.toml, aa=taa) on both backends, judged by the
temporal metrics of rfw.bench.temporal on the tiny scene at 64x36.

* Flicker on a still camera: the jittered image without a resolve (TAA with feedback 0:
  this frame's sample alone) flickers, TAA settles it, and the unjittered image does not
  flicker at all (the control that the metric reads only what changes).
* Ghosting under motion: with the camera moving sideways, turning the neighbourhood clip
  off raises the error of the last frame against a reference (the same frame rendered
  without jitter at 4x the size, box-filtered down, compared in linear HDR luminance);
  on a still camera (the control) the clip costs nothing or helps little.

* On a still camera without jitter TAA gives back this frame's image, but for the rounding
  of half floats: its clip box holds this frame's sample, so the history is not biased.

Measured on lavapipe (Mesa 25.0, 64x36, tiny scene), the same to the last digit on wgpu
and vk: flicker 0 (aa=none), 0.0068 (jittered, no resolve), 0.0005 (TAA, 14x less). With
ao off, the error against the reference under motion is 0.0102 (variance clip), 0.0120
(min/max clamp) and 0.0245 (clip off), no AA 0.0053; on a still camera 0.0028, 0.0029 and
0.0030, no AA 0.0057. Under motion TAA loses to no AA here: it blurs what moves and lags
the view-dependent shading of the floor (the highlight moves as the camera does).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from pass_scenes import tiny_scene

from rfw.bench.temporal import box_down, flicker_index, linear_luminance
from rfw.config import apply_overrides, load_config
from rfw.render import render

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "deferred_ssao_shadows.toml"
W, H = 64, 36
SETTLE = 8  # frames for the history to fill (feedback 0.9) before flicker is measured



def frames(backend, sets: list[str], n: int, output: str = "fxaa.color",
           size: tuple[int, int] = (W, H)) -> list[np.ndarray]:
    """Each of ``n`` timed frames' ``output``."""
    name, dev = backend
    cfg = apply_overrides(load_config(CONFIG), [f"size={size[0]}x{size[1]}", f"frames={n}",
                                                 *sets])
    cfg = replace(cfg, outputs=[output])
    got: list[np.ndarray] = []
    render(cfg, scene=tiny_scene(), backend=name, device=dev,
           each_frame=lambda k, frame: got.append(frame.read(output).copy()))
    return got


def flicker(backend, *sets: str) -> float:
    return flicker_index(frames(backend, list(sets), SETTLE + 12)[SETTLE:]).index


def test_taa_settles_the_flicker_of_the_jittered_image(backend):
    unjittered = flicker(backend, "aa=none")
    jittered = flicker(backend, "aa=taa", "taa.feedback=0")
    resolved = flicker(backend, "aa=taa")
    assert unjittered == 0.0  # a still camera without jitter: the same image every frame
    assert jittered > 0.003  # the jitter alone flickers (measured 0.0068)...
    assert resolved < jittered / 5  # ... and TAA settles it (measured 0.0005, 14x less)


def _cameras():
    base = tiny_scene().cameras[0]
    start = np.array(base.position)
    target = np.array(base.target)
    side = np.cross(target - start, (0.0, 1.0, 0.0))
    side *= 3.0 / np.linalg.norm(side)  # 3 m sideways over the run: about 2 px a frame
    end = [float(v) for v in start + side]
    return [float(v) for v in start], [float(v) for v in target], end, \
        [float(v) for v in target + side]


def _error(image: np.ndarray, reference: np.ndarray) -> float:
    return float(np.abs(linear_luminance(image) - linear_luminance(reference)).mean())


@pytest.fixture(scope="module")
def reference(request):
    """The last camera's frame without jitter at 4x the size, box-filtered down (linear
    HDR: alpha is coverage, color premultiplied, as TAA resolves them), per backend."""
    out = {}

    def get(backend):
        if backend[0] not in out:
            _, _, end, end_target = _cameras()
            big = frames(backend, ["aa=none", "ao=off", f"camera.position={end}",
                                   f"camera.target={end_target}"], 1, "lighting.hdr",
                         (4 * W, 4 * H))[-1]
            out[backend[0]] = box_down(big.astype(np.float32), 4)
        return out[backend[0]]

    return get


def test_clipping_the_history_keeps_motion_from_ghosting(backend, reference):
    start, target, end, end_target = _cameras()
    path = (f"camera.path.keys=[{{position={start}, target={target}}}, "
            f"{{position={end}, target={end_target}}}]")
    still = [f"camera.position={end}", f"camera.target={end_target}"]
    ref = reference(backend)

    def error(camera: list[str], clamp: str) -> float:
        last = frames(backend, ["aa=taa", "ao=off", f"taa.clamp={clamp}", *camera], 16,
                      "taa.color")[-1]
        return _error(last, ref)

    clipped, unclipped = error([path], "variance"), error([path], "off")
    assert unclipped > 1.6 * clipped  # measured 0.0245 against 0.0102 (2.4x)
    # control: on a still camera there is nothing to ghost, and no clip does no harm
    # (measured 0.0030 against 0.0028)
    assert error(still, "off") < 1.2 * error(still, "variance")


def test_a_still_unjittered_camera_gets_its_own_image_back(backend):
    name, dev = backend
    cfg = apply_overrides(load_config(CONFIG), [f"size={W}x{H}", "frames=4", "aa=taa",
                                                 "taa.jitter=0"])
    cfg = replace(cfg, outputs=["lighting.hdr", "taa.color"])
    worst = []

    def read(k, frame):
        now = frame.read("lighting.hdr").astype(np.float64)
        resolved = frame.read("taa.color").astype(np.float64)
        # two steps of a half float (2^-10 relative each), measured: at most one
        worst.append(float((np.abs(resolved - now) / (2.0 ** -9 * np.abs(now) + 1e-4)).max()))

    render(cfg, scene=tiny_scene(), backend=name, device=dev, each_frame=read)
    assert max(worst) <= 1.0, worst
