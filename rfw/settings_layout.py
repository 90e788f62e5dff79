"""A shader's settings block checked against its pass's ``Settings``, member by member.

A pass binds its settings to a uniform block by name (``u_params=self.params``); the bytes
are ``Settings.pack()``'s, the layout the shader reads is the block's. Nothing else ties
the two, so a field renamed, reordered or retyped on one side reads another field's bytes.
The block's members, reflected from the SPIR-V (``rfw.spirv.uniform_blocks``), must each
be a field that ``pack()`` writes (``Settings.layout()``), with the same name, byte offset
and type. A block may leave fields out, trailing or not: each member it declares is
checked where it is, so what it reads is what ``pack()`` wrote (skip a field with
``layout(offset = N)``). A member that is no packed field is an error, padding included:
std140 places every field where ``pack()`` does, so no block needs padding members.

Both backends check where a Settings value is bound to a uniform block, once per program
and Settings type (``check_bound_settings``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .errors import did_you_mean
from .passes import Settings
from .shaders import ShaderError
from .spirv import BlockMember, uniform_blocks


def check_settings_block(pass_name: str, settings_cls: type[Settings],
                         block: Sequence[BlockMember], file: str | Path) -> None:
    """A ShaderError naming the pass, the member and ``file`` unless every member of
    ``block`` is a field ``settings_cls.pack()`` writes, at the same offset, of the same
    type; the first problem leads, the others are counted."""
    fields = {f.name: f for f in settings_cls.layout()}
    packs = f"{settings_cls.__qualname__}.pack()"
    problems = []
    for m in block:
        what = f"pass '{pass_name}': settings block member '{m.name}' of {file}"
        f = fields.get(m.name)
        if f is None:
            problems.append(f"{what} is no field {packs} writes" +
                            did_you_mean(m.name, fields))
        elif m.offset != f.offset:
            problems.append(f"{what} is at offset {m.offset}, {packs} puts it at {f.offset}")
        elif m.type != f.type:
            problems.append(f"{what} is declared {m.type}, {packs} writes it as {f.type}")
    if problems:
        raise ShaderError(problems[0], more=problems[1:])


def check_bound_settings(program: Any, name: str, value: Any, pass_name: str) -> None:
    """Where ``value`` is a Settings bound to ``program``'s uniform block ``name``: check
    the block of every file of the program that declares it (``check_settings_block``),
    once per program and Settings type. ``program`` is either backend's, its compiled
    files in ``program.spirvs`` (none for WGSL, which is not checked)."""
    if not isinstance(value, Settings):
        return
    done = program.settings_checked
    key = (name, type(value))
    if key in done:
        return
    for spv in program.spirvs:
        block = uniform_blocks(spv.code).get(name)
        if block is not None:
            check_settings_block(pass_name, type(value), block, spv.path)
    done.add(key)
