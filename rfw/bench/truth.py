"""Ground truth for ``rfw bench``: ``--reference pathtrace[:SPP]``.

The path tracer (``configs/pathtrace.toml``, Vulkan) renders the reference of every view the
bench's variants rendered (scene, camera and size; a camera path's last frame), reused from
a cache keyed by those and by the sources that shape the reference. Each variant's run
writes its linear HDR image before tone mapping (the tonemap pass's input, from an untimed
replay of the same frames: the timed run is the run any bench does). The report then
measures every variant against the truth (:func:`errors`): HDR-FLIP (mean and 99th
percentile) and relative MSE on linear HDR, FLIP on the displayed image, each with a 95%
CI from a bootstrap over image tiles, and draws the error-versus-GPU-ms fronts per
technique family (:func:`dominance`, :mod:`rfw.bench.report.truth`).

The reference's own noise is measured too: its convergence estimate (half the difference of
the even and odd samples' means) estimates the standard error of each pixel, so the
relative MSE a perfect technique would score against it is ``mean(error² / (ref² + ε))``,
the floor under every variant's relative MSE."""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RfwError

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "pathtrace.toml"
DEFAULT_SPP = 256
MAX_SPP = 1 << 20
MAX_PER_FRAME = 64  # samples per pixel in one frame's dispatch: a GPU's watchdog allows it
REL_EPS = 0.01  # relative MSE: (x - y)² / (y² + ε), as denoising papers report it
TILE = 16  # pixels per side of a bootstrap tile
BOOT = 1000  # bootstrap resamples
HDR_FILE, LDR_FILE, ERROR_FILE, META_FILE = "hdr.exr", "ldr.png", "error.exr", "meta.json"
# what shapes a reference besides scene, camera, size and samples: a change to any of these
# renders it anew rather than reusing the cached one
SOURCES = ("passes/pathtrace", "passes/accel_build", "passes/tonemap", "shaders/common",
           "configs/pathtrace.toml", "rfw/scene", "rfw/backends/scene_data.py", "vkext/scene.py",
           "vkext/accel")


COMPONENTS = ("full", "ao", "direct", "direct_centre")
DEFAULT_AO_RADIUS = 1.0  # rt_ao's default radius


@dataclass(frozen=True)
class TruthSpec:
    """``--reference pathtrace[:COMPONENT][:SPP]``: SPP samples per pixel (``per_frame`` of
    them a frame) of one component of the truth:

    - ``full``: the whole image (radiance before tone mapping; the displayed image too);
    - ``ao`` or ``ao=R``: ambient occlusion of radius R (default 1, rt_ao's), against the
      AO the lighting pass reads (ones where nothing occludes), on pixels of the scene;
    - ``direct``: the punctual lights' direct light (no sky, no bounces) over each pixel's
      footprint, against the image with the lighting pass's ambient term off (shadows and
      anti-aliasing without the global illumination no raster pass has);
    - ``direct_centre``: the same through pixel centres only (shadows without
      anti-aliasing: a filtered shadow map's soft edge is nearer a footprint's mean than
      one ray, which would reward it for blurring)."""

    spp: int
    component: str = "full"
    ao_radius: float = DEFAULT_AO_RADIUS

    @property
    def per_frame(self) -> int:
        return max(d for d in range(1, min(self.spp, MAX_PER_FRAME) + 1) if self.spp % d == 0)

    @property
    def frames(self) -> int:
        return self.spp // self.per_frame

    @property
    def kind(self) -> str:
        return self.component.partition("=")[0]

    @property
    def text(self) -> str:
        return f"pathtrace:{self.component}:{self.spp}"

    def reference_sets(self) -> list[str]:
        """The path tracer's settings for this component."""
        if self.kind == "ao":
            return ["pt.mode=ao", f"pt.ao_radius={self.ao_radius:g}"]
        if self.kind.startswith("direct"):
            return ["pt.max_bounces=1", "pt.sky=0",
                    *(["pt.jitter=false"] if self.kind == "direct_centre" else [])]
        return []


def parse(text: str | None) -> TruthSpec | None:
    """``pathtrace``, ``pathtrace:SPP``, ``pathtrace:COMPONENT`` or
    ``pathtrace:COMPONENT:SPP`` as a :class:`TruthSpec`; None for anything else (a
    variant's label or index: the reference is one of the variants then)."""
    if text is None:
        return None
    name, _, rest = str(text).partition(":")
    if name.strip() != "pathtrace":
        return None
    spp, component, radius = DEFAULT_SPP, "full", DEFAULT_AO_RADIUS
    usage = (f"expected pathtrace[:COMPONENT][:SPP] with COMPONENT one of full, ao, ao=R, "
             f"direct, direct_centre and SPP a whole number from 1 to {MAX_SPP}, not {text!r}")
    for token in [t.strip() for t in rest.split(":")] if rest else []:
        if token.isdigit():
            if not 1 <= int(token) <= MAX_SPP:
                raise RfwError(usage, element="--reference")
            spp = int(token)
            continue
        kind, eq, value = token.partition("=")
        if kind not in COMPONENTS or (eq and kind != "ao"):
            raise RfwError(usage, element="--reference")
        if eq:
            try:
                radius = float(value)
            except ValueError:
                raise RfwError(usage, element="--reference") from None
            if not 0.0 < radius < 1e6:
                raise RfwError(f"ao radius: expected a number over 0, not {value!r}",
                               element="--reference")
        component = "ao" if kind == "ao" else kind
    if component == "ao":
        component = f"ao={radius:g}"
    return TruthSpec(spp, component, radius)


# ---------------------------------------------------------------- which references a bench needs


def camera_sets(record: dict[str, Any]) -> list[str]:
    """The ``--set camera.KEY=VALUE`` that give the path tracer the camera of ``record``'s
    image: a camera path's last frame (position, target, field of view) over the run's
    static camera, else the static camera (:func:`rfw.bench.report.images.camera_of`)."""
    from .report.images import _static_camera

    table = {k: v for k, v in _static_camera(record).items() if k != "path"}
    frames = (record.get("camera_path") or {}).get("frames") or []
    if frames:
        last = frames[-1]
        for k in ("position", "target", "yfov"):
            if last.get(k) is not None:
                table[k] = last[k]
    return [f"camera.{k}={_toml(v)}" for k, v in sorted(table.items())]


def _toml(value: Any) -> str:
    if isinstance(value, str):
        try:  # a value the settings kept as written ('[0, 1, 5]', '60')
            json.loads(value)
            return value
        except ValueError:
            return json.dumps(value)
    return json.dumps(value)


@dataclass(frozen=True)
class View:
    """One reference to render: a scene (None: the config's), camera settings and a size."""

    scene: str | None
    camera: tuple[str, ...]
    size: tuple[int, int]

    def key(self, spec: TruthSpec) -> str:
        """The cache key: the view, the samples and the sources that shape a reference."""
        h = hashlib.sha256()
        h.update(json.dumps({"scene": self.scene, "scene_bytes": _scene_digest(self.scene),
                             "camera": list(self.camera), "size": list(self.size),
                             "spp": spec.spp, "per_frame": spec.per_frame,
                             "reference_sets": spec.reference_sets(),
                             "sources": sources_digest()}, sort_keys=True).encode())
        return h.hexdigest()[:20]


def view_of(record: dict[str, Any]) -> View:
    size = tuple(record.get("size") or ())
    scene = record.get("scene_arg")  # what the run was given (None: the config's own)
    return View(scene, tuple(camera_sets(record)), size)  # type: ignore[arg-type]


def _scene_digest(scene: str | None) -> str | None:
    if scene is None or not Path(scene).is_file():
        return None  # the config's, a built-in's name (its code is in the sources)
    h = hashlib.sha256()
    with open(scene, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


_SOURCES_DIGEST: str | None = None


def sources_digest() -> str:
    """A hash of every file under :data:`SOURCES` (names and bytes)."""
    global _SOURCES_DIGEST
    if _SOURCES_DIGEST is None:
        h = hashlib.sha256()
        for rel in SOURCES:
            top = ROOT / rel
            files = sorted(top.rglob("*")) if top.is_dir() else [top]
            for f in files:
                if f.is_file() and "__pycache__" not in f.parts:
                    h.update(str(f.relative_to(ROOT)).encode() + b"\0" + f.read_bytes())
        _SOURCES_DIGEST = h.hexdigest()
    return _SOURCES_DIGEST


def cache_dir() -> Path:
    """``$RFW_CACHE_TRUTH`` if set, else ``~/.cache/rfw/truth``."""
    from .. import env

    return env.get("RFW_CACHE_TRUTH") or Path.home() / ".cache" / "rfw" / "truth"


def reference_command(view: View, spec: TruthSpec, out: Path) -> list[str]:
    import sys

    cmd = [sys.executable, "-P", "-m", "rfw.bench.reference", "--spp", str(spec.spp),
           "--per-frame", str(spec.per_frame), "--size", f"{view.size[0]}x{view.size[1]}",
           "--out", str(out)]
    if view.scene:
        cmd += ["--scene", view.scene]
    for s in [*view.camera, *spec.reference_sets()]:
        cmd += ["--set", s]
    return cmd


def render_references(out_dir: Path, records: list[dict[str, Any]], spec: TruthSpec, *,
                      timeout: float, progress: bool = True) -> Path:
    """Render (or take from the cache) the reference of every view among the runs that
    worked, into ``out_dir/reference/<key>/``; writes ``out_dir/truth.json`` mapping each
    run's variant to its reference. A reference that fails is said there (and on stderr),
    and its variants get no error numbers; the bench goes on."""
    import shutil
    import subprocess
    import sys
    import time

    from .runner import _worker, worker_env

    views: dict[str, View] = {}
    variants: dict[str, str] = {}
    for r in records:
        if r.get("error") or r.get("kind") != "rfw" or r.get("repeat") != 0:
            continue
        view = view_of(r)
        key = view.key(spec)
        views[key] = view
        variants[r["variant"]] = key
    refs: dict[str, Any] = {}
    cache = cache_dir()
    for i, (key, view) in enumerate(views.items()):
        dest = out_dir / "reference" / key
        cached = cache / key
        t = time.perf_counter()
        source = "cache" if _from_cache(cached, dest) else None
        if source is None:
            scratch = out_dir / "reference" / f".{key}.partial"
            shutil.rmtree(scratch, ignore_errors=True)
            try:
                done = _worker(reference_command(view, spec, scratch), timeout=timeout,
                               env=worker_env(), cwd=None)
            except subprocess.TimeoutExpired:
                done = None
            if done is None or done.returncode or not (scratch / META_FILE).is_file():
                why = f"timed out after {timeout:g} s" if done is None else \
                    (done.stderr.strip().splitlines() or [f"exit {done.returncode}"])[-1]
                refs[key] = {"error": why, "view": _view_json(view)}
                print(f"rfw bench: reference {i + 1}/{len(views)} failed: {why}",
                      file=sys.stderr)
                shutil.rmtree(scratch, ignore_errors=True)
                continue
            shutil.rmtree(dest, ignore_errors=True)
            os.replace(scratch, dest)
            _store(dest, cached)
            source = "rendered"
        meta = json.loads((dest / META_FILE).read_text(encoding="utf-8"))
        refs[key] = {**meta, "source": source, "folder": str(Path("reference") / key),
                     "view": _view_json(view)}
        if progress:
            print(f"[reference {i + 1}/{len(views)}] {spec.text} {view.size[0]}x{view.size[1]}"
                  f": {source} ({time.perf_counter() - t:.1f} s)", file=sys.stderr)
    path = out_dir / "truth.json"
    data = {"reference": spec.text, "spp": spec.spp, "component": spec.component,
            "reference_sets": spec.reference_sets(), "references": refs, "variants": variants}
    path.write_text(json.dumps(data, indent=1), encoding="utf-8")
    return path


def _view_json(view: View) -> dict[str, Any]:
    return {"scene": view.scene, "camera": list(view.camera), "size": list(view.size)}


def _from_cache(cached: Path, dest: Path) -> bool:
    """Copy the cached reference to ``dest``; False where there is none. A damaged entry
    (a file missing, a meta.json that is not JSON) is discarded with one warning."""
    import shutil
    import sys

    if not cached.is_dir():
        return False
    try:
        json.loads((cached / META_FILE).read_text(encoding="utf-8"))
        _copy_reference(cached, dest)
        return True
    except (OSError, ValueError) as e:
        print(f"rfw: warning: damaged reference in the cache, rendered anew: {cached} "
              f"({type(e).__name__})", file=sys.stderr)
        shutil.rmtree(cached, ignore_errors=True)
        shutil.rmtree(dest, ignore_errors=True)
        return False


def _copy_reference(src: Path, dest: Path) -> None:
    import shutil

    dest.mkdir(parents=True, exist_ok=True)
    for name in (HDR_FILE, LDR_FILE, ERROR_FILE, META_FILE):
        shutil.copyfile(src / name, dest / name)


def _store(src: Path, cached: Path) -> None:
    """Into the cache, whole or not at all (a reader never sees half a reference); a cache
    that cannot be written only costs the next bench a render."""
    import contextlib
    import shutil
    import tempfile

    with contextlib.suppress(OSError):
        cached.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{cached.name}.", dir=cached.parent))
        try:
            _copy_reference(src, tmp)
            os.replace(tmp, cached)
        except OSError:
            shutil.rmtree(tmp, ignore_errors=True)


# ---------------------------------------------------------------- errors against the truth


def _tiles(h: int, w: int, tile: int = TILE) -> np.ndarray:
    """Each pixel's tile index (row-major tiles of ``tile`` pixels a side)."""
    ty, tx = (np.arange(h) // tile), (np.arange(w) // tile)
    return (ty[:, None] * ((w + tile - 1) // tile) + tx[None, :]).reshape(-1)


def _resamples(n_tiles: int, *, boots: int = BOOT, seed: int = 0) -> np.ndarray:
    """(boots, n_tiles) counts: how often each tile is drawn in each bootstrap resample."""
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, n_tiles, size=(boots, n_tiles))
    counts = np.zeros((boots, n_tiles), np.int32)
    np.add.at(counts, (np.arange(boots)[:, None], draws), 1)
    return counts


def mean_ci(values: np.ndarray, tiles: np.ndarray, counts: np.ndarray) -> dict[str, float]:
    """The mean of per-pixel ``values`` with a 95% CI from resampling tiles (``counts`` from
    :func:`_resamples`): neighbouring pixels' errors are not independent, tiles nearly are."""
    n_tiles = counts.shape[1]
    sums = np.bincount(tiles, weights=values.astype(np.float64), minlength=n_tiles)
    npix = np.bincount(tiles, minlength=n_tiles).astype(np.float64)
    boot = (counts @ sums) / np.maximum(counts @ npix, 1)
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return {"value": float(values.mean()), "ci_lo": float(lo), "ci_hi": float(hi)}


def quantile_ci(values: np.ndarray, tiles: np.ndarray, counts: np.ndarray, q: float, *,
                bins: int = 2000) -> dict[str, float]:
    """The ``q`` quantile of ``values`` (FLIP: 0 to 1) with a 95% CI from resampling tiles,
    through per-tile histograms of ``bins`` bins (a resample is a sum of histograms)."""
    top = max(float(values.max()), 1e-12)
    b = np.minimum((values / top * bins).astype(np.int64), bins - 1)
    n_tiles = counts.shape[1]
    hist = np.zeros((n_tiles, bins), np.float64)
    np.add.at(hist, (tiles, b), 1.0)
    cdf = np.cumsum(counts @ hist, axis=1)
    idx = (cdf < q * cdf[:, -1:]).sum(axis=1)
    boot = (np.minimum(idx, bins - 1) + 0.5) / bins * top
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return {"value": float(np.quantile(values, q)), "ci_lo": float(lo), "ci_hi": float(hi)}


def _flip_map(reference: np.ndarray, test: np.ndarray, kind: str) -> np.ndarray | None:
    try:
        import flip_evaluator
    except ImportError:
        return None
    a, b = (np.ascontiguousarray(x, np.float32) for x in (reference, test))
    error_map, _, _ = flip_evaluator.evaluate(a, b, kind, applyMagma=False)
    return np.asarray(error_map, np.float32).reshape(-1)


def errors(reference_hdr: np.ndarray | None, test_hdr: np.ndarray | None,
           reference_ldr: np.ndarray | None, test_ldr: np.ndarray | None, *,
           component: str = "full", boots: int = BOOT, seed: int = 0
           ) -> dict[str, dict[str, float]]:
    """Each metric of ``test`` against the reference, as ``{value, ci_lo, ci_hi}``:
    ``hdr_flip`` and ``hdr_flip_p99`` (HDR-FLIP of linear RGB, negatives clipped),
    ``rel_mse`` (mean over pixels and channels of (x - y)² / (y² + 0.01)), ``rmse`` and,
    but for ``ao``, ``flip`` (LDR FLIP of the displayed 8-bit images, over all pixels). A metric is
    left out where its images are missing or of another shape.

    ``ao`` compares the first channels on pixels wholly on the scene (the reference's alpha
    1: rt_ao and SSAO leave the sky open, the truth has nothing there); ``direct_centre``
    the same pixels' RGB; ``direct`` every pixel the scene covers at all (edges are what
    anti-aliasing is judged on). Pixels left out take the reference's values, so FLIP's
    filters see no edge there, and count in no mean."""
    kind = component.partition("=")[0]
    out: dict[str, dict[str, float]] = {}
    if reference_hdr is not None and test_hdr is not None \
            and reference_hdr.shape[:2] == test_hdr.shape[:2]:
        shape = reference_hdr.shape[:2]
        ref = np.asarray(reference_hdr, np.float32)
        img = np.nan_to_num(np.asarray(test_hdr, np.float32), nan=0.0, posinf=1e4)
        if kind == "ao":
            ref3, img3 = (np.repeat(x[..., :1], 3, axis=2) for x in (ref, img))
        else:
            ref3, img3 = ref[..., :3], img[..., :3]
        ref3, img3 = np.maximum(ref3, 0.0), np.maximum(img3, 0.0)
        coverage = ref[..., 3] if ref.shape[2] > 3 else np.ones(shape, np.float32)
        mask = (np.ones(shape, bool) if kind == "full" else coverage > 0 if kind == "direct"
                else coverage >= 1.0)
        img3 = np.where(mask[..., None], img3, ref3)
        keep = mask.reshape(-1)
        if not keep.any():
            return out
        tiles = _tiles(*shape)[keep]
        counts = _resamples(int(_tiles(*shape).max()) + 1, boots=boots, seed=seed)
        diff2 = (img3 - ref3) ** 2
        rel = (diff2 / (ref3 * ref3 + REL_EPS)).mean(axis=2).reshape(-1)[keep]
        out["rel_mse"] = mean_ci(rel, tiles, counts)
        sq = mean_ci(diff2.mean(axis=2).reshape(-1)[keep], tiles, counts)
        out["rmse"] = {k: math.sqrt(max(v, 0.0)) for k, v in sq.items()}
        fmap = _flip_map(ref3, img3, "HDR")
        if fmap is not None:
            out["hdr_flip"] = mean_ci(fmap[keep], tiles, counts)
            out["hdr_flip_p99"] = quantile_ci(fmap[keep], tiles, counts, 0.99)
    if kind in ("full", "direct", "direct_centre") and reference_ldr is not None \
            and test_ldr is not None \
            and reference_ldr.shape[:2] == test_ldr.shape[:2]:
        a, b = (np.asarray(x)[..., :3].astype(np.float32) / 255.0
                for x in (reference_ldr, test_ldr))
        fmap = _flip_map(a, b, "LDR")
        if fmap is not None:
            tiles = _tiles(*a.shape[:2])
            counts = _resamples(int(tiles.max()) + 1, boots=boots, seed=seed)
            out["flip"] = mean_ci(fmap, tiles, counts)
    return out


def front_metric(component: str) -> str:
    """The error a component's fronts are drawn against: HDR-FLIP for radiance (``full``,
    ``direct_centre``: an RMSE of radiance is the few brightest pixels' error), the
    displayed image's FLIP for ``direct`` (anti-aliasing: FXAA works on the displayed
    image, TAA before the tone map), RMSE for the AO term (0 to 1)."""
    kind = component.partition("=")[0]
    return {"direct": "flip", "ao": "rmse"}.get(kind, "hdr_flip")


def noise_floor(reference_hdr: np.ndarray, error: np.ndarray) -> dict[str, float]:
    """What the reference's own noise adds to a perfect technique's error against it: the
    relative MSE of its estimated standard error (``error``, the pathtrace pass's
    convergence estimate) and that error's mean relative to the radiance."""
    ref = np.maximum(np.asarray(reference_hdr, np.float32)[..., :3], 0.0)
    err = np.asarray(error, np.float32)[..., :3]
    rel = (err * err / (ref * ref + REL_EPS)).mean()
    luminance = float(ref.mean())
    return {"rel_mse": float(rel),
            "rel_error": float(np.abs(err).mean() / luminance) if luminance > 0 else math.nan}


# ---------------------------------------------------------------- fronts


def family_of(record: dict[str, Any]) -> str:
    """A variant's technique family: its config and backend with the ``--vary`` choices of
    variant groups (``ao=ssao``), not of pass settings (``ssao.samples=8``): a family's
    variants are one technique at several settings."""
    config = Path(record.get("config_path") or "config").stem
    groups = [v for v in record.get("varied") or [] if "." not in v.partition("=")[0]]
    backend = record.get("requested_backend") or record.get("backend") or ""
    return config + (f"[{','.join(groups)}]" if groups else "") + (f"@{backend}" if backend
                                                                     else "")


@dataclass
class Point:
    """A variant on the error-versus-cost plane: GPU ms and an error, each with a CI."""

    label: str
    family: str
    ms: float
    ms_lo: float
    ms_hi: float
    err: float
    err_lo: float
    err_hi: float
    ms_ci: bool = True  # the GPU ms CI is a 95% CI (enough samples and runs for one)


def dominance(points: Iterable[Point]) -> dict[str, list[tuple[str, bool]]]:
    """For each point, the points that dominate it: no slower and no worse (by medians),
    better in one; ``True`` where it holds beyond the CIs (better on one axis with the two
    CIs apart)."""
    pts = list(points)
    out: dict[str, list[tuple[str, bool]]] = {p.label: [] for p in pts}
    for p in pts:
        for q in pts:
            if q is p:
                continue
            if q.ms <= p.ms and q.err <= p.err and (q.ms < p.ms or q.err < p.err):
                # beyond the CIs: better on one axis with the intervals apart (on the other
                # its median is no worse, so it is at worst within the noise there)
                apart = (q.ms_ci and p.ms_ci and q.ms_hi < p.ms_lo) or q.err_hi < p.err_lo
                out[p.label].append((q.label, apart))
    return out


def front(points: Iterable[Point]) -> list[Point]:
    """The non-dominated points by medians, cheapest first."""
    pts = list(points)
    dom = dominance(pts)
    return sorted((p for p in pts if not dom[p.label]), key=lambda p: (p.ms, p.err))
