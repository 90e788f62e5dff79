"""Files written whole or not at all."""

from __future__ import annotations

import os
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO


def check_target(path: str | Path, *, element: str | None = None) -> Path:
    """Refuse an output path that exists and is no regular file (a device, FIFO, socket or
    folder): writing there would replace it, or block, or write into a device. A symlink
    counts as what it points to. Returns ``path``."""
    from .errors import RfwError

    path = Path(path)
    try:
        st = os.stat(path)
    except OSError:  # nothing there (or unreachable): the write itself says why it fails
        return path
    if not stat.S_ISREG(st.st_mode):
        raise RfwError(f"exists and is {_kind(st.st_mode)}, not a regular file: refused as "
                       "an output", file=str(path), element=element)
    return path


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a folder"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "a special file"


def atomic_write(path: str | Path, write: Callable[[BinaryIO], object]) -> None:
    """Write ``path`` through ``write(file)`` into a temporary file beside it, then rename:
    readers and failures never see half a file. The file gets the permissions ``open()``
    would give it (mkstemp's are 0600); an OSError names ``path``, not the temporary file.
    A ``path`` that exists and is no regular file is refused (:func:`check_target`)."""
    def named(tmp: str) -> None:
        with open(tmp, "wb") as f:
            write(f)

    atomic_file(path, named)


def atomic_file(path: str | Path, write: Callable[[str], object]) -> None:
    """:func:`atomic_write` for a writer that takes a file name (``write(tmp_name)``), as
    OpenEXR's does."""
    path = check_target(path)  # a device or FIFO there is refused, never replaced
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        os.close(fd)
    except OSError as e:
        raise OSError(e.errno, e.strerror, str(path)) from None
    try:
        write(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except OSError as e:
        Path(tmp).unlink(missing_ok=True)
        raise OSError(e.errno, e.strerror, str(path)) from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def inside(root: str | Path, name: str | Path) -> Path:
    """``root / name``, refused unless it resolves (symlinks included) inside ``root``: a
    name that comes from a config or a graph can never write elsewhere."""
    from .errors import RfwError

    base = Path(root).resolve()
    path = (base / name).resolve()
    if path != base and base not in path.parents:
        raise RfwError(f"'{name}' would be written outside the output folder {base}",
                       file=str(root))
    return path


# EXR channel names by channel count: one channel is luminance, as OpenEXR names it
EXR_CHANNELS = {1: ("Y",), 2: ("R", "G"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}


def is_float_image(image: Any) -> bool:
    """Whether ``image`` (a readback) holds floats: what an EXR can keep exactly."""
    import numpy as np

    return np.issubdtype(image.dtype, np.floating)


def write_exr(path: str | Path, image: Any) -> None:
    """``image`` (H, W, C) float16 or float32 as an OpenEXR file, written whole or not at
    all: half channels for float16, float channels for float32, ZIP (lossless)
    compression, so reading it back gives the same bits. Other dtypes are refused."""
    import numpy as np
    import OpenEXR

    if image.dtype not in (np.float16, np.float32) or image.ndim != 3 \
            or image.shape[2] not in EXR_CHANNELS:
        raise ValueError(f"an EXR holds (H, W, 1-4) float16 or float32, not {image.dtype} "
                         f"{image.shape}")
    channels = {c: np.ascontiguousarray(image[..., i])
                for i, c in enumerate(EXR_CHANNELS[image.shape[2]])}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}

    def write(tmp: str) -> None:  # OpenEXR writes to a file name
        with OpenEXR.File(header, channels) as f:
            f.write(tmp)

    atomic_file(path, write)


def read_exr(path: str | Path) -> Any:
    """An EXR :func:`write_exr` wrote, as (H, W, C) in its stored dtype (channels in
    R, G, B, A or Y order)."""
    import numpy as np
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as f:
        ch = f.channels()
        for names in EXR_CHANNELS.values():
            if set(ch) == set(names):
                return np.stack([ch[n].pixels for n in names], axis=2)
    raise ValueError(f"{path}: unexpected EXR channels {sorted(ch)}")


FAILED_MARK = "RUN-FAILED.txt"  # older rfw's mark of a failed run: a good run removes it


def to_png_array(image: Any, fmt: str) -> Any:
    """8-bit RGBA for a PNG: unorm as is, floats clamped, depth and single channels grey."""
    import numpy as np

    from .graph.formats import format_info

    info = format_info(fmt)
    a = image
    if a.dtype != np.uint8:
        a = a.astype(np.float32)
        if info.kind in ("unorm",):
            a = a / np.iinfo(image.dtype).max
        a = np.clip(a, 0.0, 1.0) * 255 + 0.5
        a = a.astype(np.uint8)
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    if a.shape[2] == 2:
        a = np.concatenate([a, np.zeros_like(a[..., :1])], axis=2)
    if a.shape[2] == 3:
        a = np.concatenate([a, np.full_like(a[..., :1], 255)], axis=2)
    if fmt.startswith("bgra") or fmt.startswith("VK_FORMAT_B8G8R8A8"):
        a = a[..., [2, 1, 0, 3]]
    return a


def png_bytes(image: Any, fmt: str) -> bytes:
    """``image`` as the PNG ``rfw run`` writes for it (:func:`to_png_array`)."""
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(to_png_array(image, fmt), "RGBA").save(buf, format="PNG")
    return buf.getvalue()


def exr_names(images: dict[str, Any], formats: dict[str, str], *,
              file: str | None = None) -> list[str]:
    """The outputs ``--exr`` writes as ``<output>.exr`` too: those read back as floats
    (float formats, depth32float). 8-bit and integer outputs keep their exact values in
    their PNG and get no EXR; a run with no float output at all is an RfwError."""
    from .errors import RfwError

    names = [n for n, image in images.items() if is_float_image(image)]
    if not names:
        raise RfwError("writes float outputs only, and this run has none (" + ", ".join(
            f"{n}: {formats[n]}" for n in images) + "): drop --exr or list a float "
            "output in 'outputs'", file=file, element="--exr")
    return names


def write_run(out_dir: Path, images: dict[str, Any], formats: dict[str, str],
              timings: dict[str, Any], *, exr: bool = False,
              source: str | None = None) -> list[Path]:
    """What ``rfw run`` writes: ``<output>.png`` per image (with ``exr``, ``<output>.exr``
    too for each float one: :func:`exr_names`), then ``timings.json`` (last: it marks a
    complete run), each written atomically and refused unless inside ``out_dir``."""
    import json

    floats = exr_names(images, formats, file=source) if exr else []
    pngs = [inside(out_dir, f"{name}.png") for name in images]
    exrs = [inside(out_dir, f"{name}.exr") for name in floats]
    timings_path = inside(out_dir, "timings.json")
    out_dir.mkdir(parents=True, exist_ok=True)
    for path, (name, image) in zip(pngs, images.items(), strict=True):
        data = png_bytes(image, formats[name])
        atomic_write(path, lambda f, d=data: f.write(d))
    for path, name in zip(exrs, floats, strict=True):
        write_exr(path, images[name])
    atomic_write(timings_path, lambda f: f.write(json.dumps(timings, indent=2).encode()
                                                 + b"\n"))
    return [*pngs, *exrs, timings_path]
