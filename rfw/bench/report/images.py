"""The report's "Images" section: each variant's output against the reference's (PSNR, FLIP or
SSIM, a difference image with its legend), compared only where both rendered the same view
from the same camera, with the frame time change next to it. The pixel work is
:mod:`rfw.bench.images`."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ...errors import check_identifier
from ...fileio import inside
from ..images import compare, diff_legend, load_png, save_png, scale_text, scaled_diff
from ..stats import MIN_RUNS, MIN_SAMPLES, change_text
from ..summary import VariantSummary
from .devices import Parts, _by_device, _report_devices, device_of
from .document import Cell, Cells, Doc, Img, db


def _pick_reference(rfw: list[VariantSummary], reference: str | int | None) -> VariantSummary:
    done = [v for v in rfw if v.ok and v.image]
    if reference is None:
        return done[0]
    if isinstance(reference, int) or str(reference).isdigit():
        i = int(reference)
        if not 0 <= i < len(rfw):
            raise ValueError(f"--reference {i}: there are {len(rfw)} variants (0..{len(rfw) - 1})")
        return rfw[i]
    for v in rfw:
        if v.label == reference:
            return v
    raise ValueError(f"--reference '{reference}': no such variant "
                     f"({', '.join(v.label for v in rfw)})")


def image_camera(v: VariantSummary) -> tuple[Any, str]:
    """The camera of ``v``'s image (its run's last timed frame): a key that is equal for two
    runs that rendered the same view, and the camera in words."""
    record = next((r for r in v.records if r.get("image")), v.first)
    return camera_of(record)


def camera_of(record: dict[str, Any]) -> tuple[Any, str]:
    """The camera a run's image was rendered from, as :func:`image_camera` gives it: along a
    camera path the path's last frame (``camera_path`` of the record), else the static camera
    (the config's ``[camera]`` and the run's ``camera.*`` settings, on the run's scene)."""
    scene = record.get("scene")
    path = record.get("camera_path") or {}
    frames = path.get("frames") or []
    if frames:
        last = frames[-1]
        key = ("path", scene, *(tuple(round(float(x), 5) for x in last.get(k) or ())
                                for k in ("position", "target")),
               round(float(last.get("yfov") or 0.0), 4))
        return key, (f"{path.get('kind', 'camera')} path, last frame, "
                     f"t={float(last.get('t', 1.0)):.3g}")
    table = _static_camera(record)
    shown = ", ".join(f"{k}={_short(v)}" for k, v in table.items())
    return ("static", scene, json.dumps(table, sort_keys=True)), (
        "static camera" + (f" ({shown})" if shown else ""))


def _short(value: Any) -> str:
    if isinstance(value, list):
        return "[" + ",".join(_short(x) for x in value) + "]"
    return f"{value:g}" if isinstance(value, float) else str(value)


def _static_camera(record: dict[str, Any]) -> dict[str, Any]:
    """The static camera's keys of a run: its config's ``[camera]`` with the run's
    ``camera.*`` settings applied, without the path (the config read as the run read it;
    where it cannot be read any more, the settings as written)."""
    sets = [s for s in record.get("settings") or []
            if s.partition("=")[0].strip() == "camera"
            or s.partition("=")[0].strip().startswith("camera.")]
    if record.get("config_path"):
        from ...config import apply_overrides, load_config

        try:
            cfg = apply_overrides(load_config(record["config_path"]), sets)
        except (OSError, ValueError):  # moved or changed since: the settings are all we have
            pass
        else:
            return {k: v for k, v in (cfg.camera or {}).items() if k != "path"}
    out: dict[str, Any] = {}
    for s in sets:
        key, _, value = s.partition("=")
        key = key.strip()
        if key != "camera.path" and not key.startswith("camera.path."):
            out[key.removeprefix("camera.") or key] = value.strip()
    return out


def image_comparisons(out_dir: Path, rfw: list[VariantSummary],
                      reference: str | int | None = None,
                      pooled: list[VariantSummary] | None = None, *,
                      diff_scale: str = "own"
                      ) -> tuple[VariantSummary | None, list[dict[str, Any]]]:
    """Each variant's output against the reference: PSNR, FLIP, difference PNGs (written to
    ``out_dir/images``). Variants whose image has another shape, or was rendered from another
    camera (:func:`image_camera`), are compared with nothing (``camera`` says which).
    ``rfw`` may hold per-device rows (:func:`split_devices`); ``--reference`` then names or
    numbers a variant of ``pooled``, the variants as run. ``diff_scale``: see
    :func:`write_report`; each row's ``scale`` is the top of its difference image's scale."""
    if not any(v.ok and v.image for v in rfw):
        return None, []
    ref = _pick_reference(pooled if pooled is not None else rfw, reference)
    if not ref.image:
        return ref, []
    ref_img = load_png(inside(out_dir, ref.image))
    ref_cam, ref_text = image_camera(ref)
    rows = []
    for i, v in enumerate(rfw):
        if not v.image:
            continue
        img = load_png(inside(out_dir, v.image))
        row: dict[str, Any] = {"variant": v, "image": v.image}
        cam, text = image_camera(v)
        if cam != ref_cam:  # another view: a PSNR would measure the views, not the technique
            row["camera"] = (f"different {'scenes' if cam[1] != ref_cam[1] else 'cameras'}: "
                             f"not compared (reference: {ref_text}; this: {text})")
        elif img.shape == ref_img.shape:
            c = compare(ref_img, img)
            name = check_identifier("variant id", v.records[0].get("variant_id"))
            if v.base:  # one device's row: its files apart from the variant's other rows
                name += f".{i}"
            row.update(psnr=c["psnr"], diff_max=c["diff_max"], flip=c.get("flip"),
                       ssim=c.get("ssim"), name=name, abs_diff=c["abs_diff"])
            if "flip_map" in c:
                fmap = Path("images") / f"{name}.flip.png"
                save_png(inside(out_dir, fmap), c["flip_map"])
                row["flip_map"] = str(fmap)
        rows.append(row)
    write_diffs(out_dir, rows, diff_scale)
    return ref, rows


def write_diffs(out_dir: Path, rows: list[dict[str, Any]], diff_scale: str) -> None:
    """Each compared row's difference image and legend (``images/<name>.diff.png`` and
    ``.diff_legend.png``, or the row's ``files``): from 0 to its own largest difference
    (``own``), or to the largest of all ``rows`` (``shared``); sets the row's ``diff``,
    ``legend`` and ``scale``."""
    if diff_scale not in ("own", "shared"):
        raise ValueError(f"diff_scale: expected 'own' or 'shared', not {diff_scale!r}")
    compared = [r for r in rows if "abs_diff" in r]
    shared = max((r["diff_max"] for r in compared), default=0)
    for r in compared:
        top = shared if diff_scale == "shared" else r["diff_max"]
        own = r["diff_max"] if diff_scale == "shared" else None
        diff, legend = r.get("files") or (Path("images") / f"{r['name']}.diff.png",
                                          Path("images") / f"{r['name']}.diff_legend.png")
        save_png(inside(out_dir, diff), scaled_diff(r.pop("abs_diff"), top))
        diff_legend(inside(out_dir, legend), top, own_max=own)
        r.update(diff=str(diff), legend=str(legend), scale=scale_text(top, own_max=own))


def diff_cell(r: dict[str, Any]) -> Cell:
    """A row's difference image with its legend and its scale in words."""
    return Cells([Img(r["diff"], "diff"), Img(r["legend"], "legend", 160), r["scale"]])


def _images(doc: Doc, out_dir: Path, rfw: list[VariantSummary],
            reference: str | int | None, pooled: list[VariantSummary], *,
            diff_scale: str = "own", parts: Parts) -> None:
    ref, rows = image_comparisons(out_dir, rfw, reference, pooled, diff_scale=diff_scale)
    if ref is None:
        return
    doc.h(2, "Images")
    has_flip = any(r.get("flip") is not None for r in rows)
    devices = _report_devices(pooled)
    # the reference's statistics on each device it ran on (a per-device row: its one)
    ref_on = dict(parts[id(ref)] if id(ref) in parts else _by_device(ref))
    scale = ("colour-mapped from black (0) to the largest difference of all the report's "
             "images (`--diff-scale shared`: colours compare across rows; each legend states "
             "the scale and the image's own largest difference)"
             if diff_scale == "shared" else
             "colour-mapped from black (0) to the largest difference of that image: each "
             "image has its own scale, stated below it (`scale 0-4/255`), so the same colour "
             "means different differences in different rows (`--diff-scale shared` draws "
             "them all on one scale)")
    doc.p(f"Reference: **{ref.label}**; image differences next to the time differences "
          f"(frame GPU ms, median). Difference: |reference - variant|, max over RGB, {scale}. "
          "`vs reference`: `*` where the 95% CIs of the two medians do not overlap, "
          f"`(n.s.)` where they do (not a result), no mark below {MIN_SAMPLES} samples or "
          f"{MIN_RUNS} runs (e.g. `(n=3<6: no mark)`). "
          + ("The runs measured several devices: each row is compared with the reference's "
             "runs on the same device; where the reference has none there, the change has no "
             "mark. " if len(devices) > 1 else "")
          + ("FLIP: NVIDIA's perceptual error (LDR, 67 pixels per degree; 0 = identical), "
             "magma error map." if has_flip else "SSIM from scikit-image (FLIP is not "
                                                 "installed)."))
    if any(r.get("camera") for r in rows):
        doc.p("**Different cameras:** a row marked `different cameras: not compared` rendered "
              "another view than the reference (a camera path's last frame, another static "
              "camera or another scene; from `camera_path` and the camera settings in "
              "`results.jsonl`). A PSNR or FLIP between two views measures the views, not the "
              "technique, so none is given; compare it with a variant run from the same "
              "camera (`--reference`).")
    headers = ["variant", "image", "difference", *(["FLIP map"] if has_flip else []), "PSNR",
               "FLIP" if has_flip else "SSIM", "GPU ms", "vs reference"]
    ref_gpu = ref.frame.get("gpu_ms")
    table = []
    for r in rows:
        label = r["variant"].label
        own_gpu = r["variant"].frame.get("gpu_ms")
        own_ms = (own_gpu or {}).get("median")
        cells: list[Cell] = [label, Img(r["image"], label)]
        cells.append(r["camera"] if r.get("camera") else
                     diff_cell(r) if r.get("diff") else "other size")
        if has_flip:
            cells.append(Img(r["flip_map"], "flip") if r.get("flip_map") else "-")
        cells.append("not compared" if r.get("camera") else db(r.get("psnr")))
        metric = r.get("flip") if has_flip else r.get("ssim")
        cells.append("not compared" if r.get("camera") else
                     "-" if metric is None else f"{metric:.4f}")
        cells.append("-" if own_ms is None else f"{own_ms:.3f}")
        if r["variant"] is ref or r["variant"].base == ref.label:
            cells.append("reference")
        elif len(devices) == 1:
            cells.append(change_text(ref_gpu, own_gpu))
        else:  # against the reference on this row's device only
            device = device_of(r["variant"].first)
            same = ref_on.get(device)
            if same is None:
                change = change_text(ref_gpu, own_gpu).split(" ")[0]
                cells.append(f"{change} (reference not run on {device}: no mark)")
            else:
                cells.append(change_text(same.frame.get("gpu_ms"), own_gpu))
        table.append(cells)
    doc.table(headers, table)
