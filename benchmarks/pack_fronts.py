"""Pack the benches of ``benchmarks/truth_fronts.sh`` for the repository (or for the trip back
from a GPU machine, at most 16 MiB a file): every report, table and chart as written, the
references' displayed images and metadata, and each variant's first image, shrunk to
``--thumb`` pixels wide (the numbers were measured on the full images before). Left behind:
the linear EXRs (tens of MiB each at 1280x720), the repeats' images, and the Images
section's differences between variants (the report links them; they are not the truth's).

    python benchmarks/pack_fronts.py OUT_FOLDER PACK.tgz [--thumb 192]
"""

from __future__ import annotations

import argparse
import io
import tarfile
from pathlib import Path

KEEP = {".md", ".csv", ".json", ".jsonl", ".txt"}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("folder", type=Path)
    ap.add_argument("pack", type=Path)
    ap.add_argument("--thumb", type=int, default=192)
    args = ap.parse_args()
    from PIL import Image

    with tarfile.open(args.pack, "w:gz") as tar:
        for path in sorted(args.folder.rglob("*")):
            if not path.is_file():
                continue
            rel = path.relative_to(args.folder.parent)
            if "runs" in path.parts and (path.parent.name != "r0" or path.suffix != ".png"):
                continue  # records are in results.jsonl; the report shows first runs' images
            if "images" in path.parts:
                continue  # the Images section's differences between variants: not the truth's
            if path.suffix in KEEP:
                tar.add(path, arcname=str(rel))
            elif path.suffix == ".png":
                whole = "charts" in path.parts or path.name.endswith("legend.png")
                if whole:
                    tar.add(path, arcname=str(rel))
                    continue
                with Image.open(path) as im:
                    im = im.convert("RGB")
                    if im.width > args.thumb:
                        im = im.resize((args.thumb, round(im.height * args.thumb / im.width)),
                                       Image.Resampling.LANCZOS)
                    data = io.BytesIO()
                    im.save(data, "PNG", optimize=True)
                info = tarfile.TarInfo(str(rel))
                info.size = data.tell()
                data.seek(0)
                tar.addfile(info, data)
    print(f"{args.pack}: {args.pack.stat().st_size / 2**20:.1f} MiB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
