"""Runs one group of the API corpus (``tests/api/corpus.py``) and prints what each case
raised, as JSON: ``python -m tests.api.corpus_harness GROUP TMPDIR`` from the repository root.

The files the cases name or write next to (the config, the shader, a saved result) are
hashed before and after, so a refused call that destroys or changes one is seen.
"""

from __future__ import annotations

import hashlib
import json
import sys
import traceback
from pathlib import Path

import numpy as np

import rfw
from rfw.testing import run_pass

from .corpus import CASES

ROOT = Path(__file__).resolve().parents[2]

# a pass made in code that lives in no module: what a notebook cell defines
PASS_CELL = '''
def make_pass(pass_id, *, shader="invert.comp.glsl", shader_source=None, folder=None):
    class CellPass(rfw.ComputePass):
        """A pass class from a cell."""
        inputs = {"color": rfw.Tex2D()}
        outputs = {"inverted": rfw.Tex2D("rgba8unorm", size_of="color")}
    CellPass.shader, CellPass.shader_source = shader, shader_source
    return rfw.register_pass(pass_id, **({} if folder is None else {"folder": folder}))(
        CellPass)
'''


def hashes(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def namespace(group: str, tmp: Path) -> dict:
    ns = {"rfw": rfw, "np": np, "run_pass": run_pass, "__name__": "corpus_cell"}
    if group == "result":
        ns["R"] = rfw.run(rfw.load("configs/flat.toml", size=(16, 9)), backend="wgpu")
        ns["GOOD"], ns["FRESH"] = str(tmp / "good"), str(tmp / "fresh")
        ns["R"].save(ns["GOOD"])
    if group == "passes":
        ns["GLSL"] = (ROOT / "examples" / "invert.comp.glsl").read_text()
        exec(PASS_CELL, ns)  # the class must come from no file
    if group == "ray":
        ns["V"] = np.array([[-1, -1, 0], [1, -1, 0], [0, 1, 0]], np.float32)
        ns["I"] = np.array([[0, 1, 2]], np.int32)
        ns["O"] = np.array([[0, 0, 1], [5, 5, 1]], np.float32)
        ns["D"] = np.array([[0, 0, -1], [0, 0, -1]], np.float32)
        ns["RS"] = rfw.RayScene(ns["V"], ns["I"])
    return ns


def outcome(code: str, ns: dict) -> dict:
    try:
        exec(compile(code, "<corpus>", "exec"), dict(ns))
    except Exception as e:  # what the case raised, judged by the test
        last = traceback.extract_tb(e.__traceback__)[-1]
        return {"raised": True, "type": type(e).__name__, "message": str(e),
                "rfw": isinstance(e, rfw.RfwError), "type_error": isinstance(e, TypeError),
                "value_error": isinstance(e, ValueError),
                "rfw_type": isinstance(e, rfw.RfwTypeError), "last_file": last.filename}
    return {"raised": False}


def main() -> None:
    group, tmp = sys.argv[1], Path(sys.argv[2])
    watched = {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in
               (ROOT / "configs" / "flat.toml", ROOT / "examples" / "invert.comp.glsl")}
    try:
        ns = namespace(group, tmp)
    except rfw.RfwError as e:  # no vk, no ray queries: the group is skipped
        print(json.dumps({"skip": str(e)}))
        return
    before = hashes(tmp / "good") if group == "result" else {}
    cases = {cid: outcome(code, ns) for g, cid, code, _, _ in CASES if g == group}
    after = hashes(tmp / "good") if group == "result" else {}
    changed = [str(p) for p, h in watched.items() if hashlib.sha256(p.read_bytes()).hexdigest()
               != h]
    print(json.dumps({"cases": cases, "before": before, "after": after,
                      "changed": changed}))


if __name__ == "__main__":
    main()
