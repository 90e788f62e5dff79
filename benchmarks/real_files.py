"""Render real scene files nobody here wrote, as they come, and say what happened to each.

Every glTF 2.0, OBJ, PLY, STL and OFF file under ``--root`` (default: Debian's
``assimp-testmodels``, ``apt-get install assimp-testmodels``) is judged by the Khronos glTF
validator (glTF only; npm's ``gltf-validator`` run by node), then rendered by the real CLI,
``python -m rfw.cli run CONFIG --scene FILE --size 64x64 --frames 1``, on each backend.
One JSON line per file goes to ``OUT/real_files.jsonl``: the file, the validator's verdict,
per backend the exit code, the warning lines, the error line, whether a traceback was
printed and how many pixels differ from the clear colour, and whether the backends' images
are identical. ``OUT/summary.json`` counts them: renders, refused (with the reason), needs
an extension (which), and files the validator rejects.

    npm install --prefix /tmp/gv gltf-validator@2.0.0-dev.3.10
    .venv/bin/python benchmarks/real_files.py --validator /tmp/gv --out OUT [--backends wgpu,vk]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
SUFFIXES = (".gltf", ".glb", ".obj", ".ply", ".stl", ".off")
DEFAULT_ROOT = Path("/usr/share/assimp/models")

# node: validate each file named on stdin (one per line), one JSON line each
_VALIDATE_JS = r"""
const fs = require("fs"), path = require("path"), readline = require("readline");
const validator = require(process.argv[2]);
const rl = readline.createInterface({input: process.stdin});
const files = [];
rl.on("line", (l) => { if (l) files.push(l); });
rl.on("close", async () => {
  for (const f of files) {
    let out;
    try {
      const r = await validator.validateBytes(new Uint8Array(fs.readFileSync(f)), {
        uri: path.basename(f), maxIssues: 50,
        externalResourceFunction: (uri) => new Promise((ok, no) => {
          fs.readFile(path.resolve(path.dirname(f), decodeURIComponent(uri)),
                      (e, d) => e ? no(e.toString()) : ok(d));
        })});
      const msgs = r.issues.messages || [];
      out = {file: f, errors: r.issues.numErrors, warnings: r.issues.numWarnings,
             codes: [...new Set(msgs.filter((m) => m.severity === 0).map((m) => m.code))],
             extensions: (r.info && r.info.extensionsUsed) || [],
             required: (r.info && r.info.extensionsRequired) || []};
    } catch (e) {
      out = {file: f, errors: 1, warnings: 0, codes: ["UNREADABLE"], extensions: [],
             required: [], exception: String(e).slice(0, 200)};
    }
    console.log(JSON.stringify(out));
  }
});
"""


def gltf_version(path: Path) -> str | None:
    """The asset.version of a .gltf or .glb, or None when it cannot be read."""
    try:
        data = path.read_bytes()
        if data[:4] == b"glTF":
            if struct.unpack_from("<I", data, 4)[0] != 2:
                return "1.0"
            size = struct.unpack_from("<I", data, 12)[0]
            data = data[20:20 + size]
        return str(json.loads(data.decode("utf-8-sig"))["asset"]["version"])
    except (OSError, ValueError, KeyError, TypeError, struct.error):
        return None


def find_files(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob("*") if p.suffix.lower() in SUFFIXES and p.is_file())


def validate(files: list[Path], validator: Path | None) -> dict[str, dict]:
    """The validator's report per glTF file; empty when node or the validator is missing."""
    module = validator / "node_modules" / "gltf-validator" if validator else None
    if not files or module is None or not module.exists() or shutil.which("node") is None:
        return {}
    with tempfile.NamedTemporaryFile("w", suffix=".js", delete=False) as js:
        js.write(_VALIDATE_JS)
    try:
        run = subprocess.run(["node", js.name, str(module)], input="\n".join(map(str, files)),
                             capture_output=True, text=True, timeout=1800)
    finally:
        os.unlink(js.name)
    out = {}
    for line in run.stdout.splitlines():
        if line.startswith("{"):
            r = json.loads(line)
            out[r.pop("file")] = r
    return out


def render(path: Path, backend: str, config: str, size: str, out: Path) -> dict:
    """One ``rfw run`` of ``path``: exit code, warning and error lines, pixels covered."""
    if out.exists():
        shutil.rmtree(out)
    cmd = [sys.executable, "-m", "rfw.cli", "run", config, "--scene", str(path), "--size",
           size, "--frames", "1", "--out", str(out), "--backend", backend]
    start = time.perf_counter()
    try:
        run = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=ROOT)
        code, err = run.returncode, run.stderr
    except subprocess.TimeoutExpired as e:
        code, err = "timeout", (e.stderr or b"").decode(errors="replace") \
            if isinstance(e.stderr, bytes) else (e.stderr or "")
    lines = err.splitlines()
    r = {"exit": code, "seconds": round(time.perf_counter() - start, 2),
         "warnings": [ln.removeprefix("rfw: warning: ").replace(str(path), "FILE")
                      for ln in lines if ln.startswith("rfw: warning:")],
         "error": next((ln.removeprefix("rfw: error: ").replace(str(path), "FILE")
                        for ln in lines if ln.startswith("rfw: error:")), None),
         "traceback": "Traceback (most recent call last)" in err}
    pngs = sorted(out.glob("*.png")) if code == 0 else []
    if pngs:
        rgb = np.asarray(Image.open(pngs[0]).convert("RGB"), np.int64)
        # the flat pass clears to black: any other pixel is something drawn
        r["covered"] = int((rgb.sum(axis=-1) > 0).sum())
        r["image"] = rgb
    return r


def reason(r: dict) -> str:
    """A refusal's reason, without the file and the element's numbers."""
    text = r.get("error") or ("traceback" if r.get("traceback") else f"exit {r['exit']}")
    text = text.removeprefix("FILE: ")
    return re.sub(r"\[\d+\]", "[N]", text)[:160]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", type=Path, default=DEFAULT_ROOT)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--validator", type=Path, default=None,
                    help="folder whose node_modules holds gltf-validator")
    ap.add_argument("--backends", default="wgpu,vk")
    ap.add_argument("--config", default="configs/flat.toml")
    ap.add_argument("--size", default="64x64")
    ap.add_argument("--only", default="",
                    help="comma-separated substrings: a file's path must contain one")
    args = ap.parse_args(argv)
    only = args.only.split(",")
    files = [p for p in find_files(args.root) if any(o in str(p) for o in only)]
    backends = [b for b in args.backends.split(",") if b]
    gltf = [p for p in files if p.suffix.lower() in (".gltf", ".glb")]
    versions = {p: gltf_version(p) for p in gltf}
    v2 = [p for p in gltf if (versions[p] or "").startswith("2")]
    reports = validate(v2, args.validator)
    args.out.mkdir(parents=True, exist_ok=True)
    counts: Counter = Counter()
    same: list[bool] = []
    refused: Counter = Counter()
    needs: Counter = Counter()
    with tempfile.TemporaryDirectory() as tmp, \
            open(args.out / "real_files.jsonl", "w") as log:
        for path in files:
            rel = str(path.relative_to(args.root))
            row: dict = {"file": rel, "format": path.suffix.lower().lstrip(".")}
            if path in versions and not (versions[path] or "").startswith("2"):
                row["skipped"] = f"glTF {versions[path] or 'unreadable'}, not 2.0"
                counts["skipped (not glTF 2.0)"] += 1
                log.write(json.dumps(row) + "\n")
                continue
            report = reports.get(str(path))
            if report is not None:
                row["validator"] = report
                row["valid"] = report["errors"] == 0
            results = {b: render(path, b, args.config, args.size, Path(tmp) / b)
                       for b in backends}
            images = [r.pop("image") for r in results.values() if "image" in r]
            if len(images) == len(backends) > 1:
                row["same_image"] = all(np.array_equal(images[0], i) for i in images[1:])
                same.append(row["same_image"])
            row["backends"] = results
            first = results[backends[0]]
            # mesh files have no validator: "mesh file" stands for the verdict
            judged = "mesh file" if "valid" not in row else \
                "valid" if row["valid"] else "invalid"
            if any(r.get("traceback") for r in results.values()):
                verdict = "TRACEBACK"
            elif first["exit"] == 0 and first.get("covered", 0) > 0:
                verdict = "renders"
            elif first["exit"] == 0:
                verdict = "renders nothing"
            else:
                missing = re.search(r"extensionsRequired: (\S+?),? .*not supported",
                                    first.get("error") or "")
                verdict = "needs extension" if missing else "refused"
                if missing:
                    needs[missing.group(1)] += 1
                else:
                    refused[f"{judged}: {reason(first)}"] += 1
            row["verdict"] = verdict
            counts[f"{verdict} ({judged})"] += 1
            log.write(json.dumps(row) + "\n")
            log.flush()
            print(f"{verdict:16} ({judged}) {rel}", flush=True)
    summary = {"root": str(args.root), "files": len(files), "backends": backends,
               "config": args.config, "size": args.size, "counts": dict(counts),
               "refused": dict(refused.most_common()), "needs_extension": dict(needs),
               "validated": bool(reports),
               "same_image": dict(Counter(str(r) for r in same))}
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
