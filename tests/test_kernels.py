"""The kernel table (core/vk/kernels.py) against the compiled shaders, and the shared constants against the GLSL.

A small SPIR-V reader (the words of the module: OpName, OpDecorate Binding/DescriptorSet, OpMemberDecorate Offset,
OpExecutionMode LocalSize, the push-constant variable's struct type) gives each shader's real interface; the table
must say the same, so a binding or push-constant field changed in GLSL but not in Python fails here, not on a GPU.
"""
import pathlib
import re
import struct
import sys

import pytest

from gs_ibl_addon.core.vk import constants
from gs_ibl_addon.core.vk.kernels import KERNELS

ROOT = pathlib.Path(__file__).resolve().parents[1]
SPV = ROOT / "gs_ibl_addon" / "shaders"

# opcodes and enums of the SPIR-V specification used here
OP_NAME, OP_EXECUTION_MODE, OP_TYPE_INT, OP_TYPE_FLOAT, OP_TYPE_STRUCT = 5, 16, 21, 22, 30
OP_TYPE_POINTER, OP_VARIABLE, OP_DECORATE, OP_MEMBER_DECORATE = 32, 59, 71, 72
DEC_BLOCK, DEC_BUFFER_BLOCK, DEC_BINDING, DEC_SET, DEC_OFFSET = 2, 3, 33, 34, 35
SC_UNIFORM, SC_PUSH_CONSTANT, SC_STORAGE_BUFFER = 2, 9, 12
EXEC_LOCAL_SIZE = 17


def _string(words: list[int]) -> str:
    raw = b"".join(struct.pack("<I", w) for w in words)
    return raw.split(b"\0", 1)[0].decode()


def reflect(path: pathlib.Path) -> dict:
    """{'bindings': {binding: block name}, 'sets': {set}, 'push': [(offset, type)], 'local_size': (x, y, z)}"""
    data = path.read_bytes()
    words = struct.unpack(f"<{len(data) // 4}I", data)
    assert words[0] == 0x07230203, f"{path.name} is not SPIR-V"
    names, types, pointers, variables = {}, {}, {}, []
    binding, dset, offsets, local = {}, {}, {}, None
    i = 5
    while i < len(words):
        count, op = words[i] >> 16, words[i] & 0xFFFF
        args = list(words[i + 1:i + count])
        if op == OP_NAME:
            names[args[0]] = _string(args[1:])
        elif op == OP_EXECUTION_MODE and args[1] == EXEC_LOCAL_SIZE:
            local = tuple(args[2:5])
        elif op == OP_TYPE_INT:
            types[args[0]] = "int" if args[2] else "uint"
        elif op == OP_TYPE_FLOAT:
            types[args[0]] = "float"
        elif op == OP_TYPE_STRUCT:
            types[args[0]] = ("struct", args[1:])
        elif op == OP_TYPE_POINTER:
            pointers[args[0]] = (args[1], args[2])
        elif op == OP_VARIABLE:
            variables.append((args[1], args[0], args[2]))  # (id, pointer type, storage class)
        elif op == OP_DECORATE and args[1] == DEC_BINDING:
            binding[args[0]] = args[2]
        elif op == OP_DECORATE and args[1] == DEC_SET:
            dset[args[0]] = args[2]
        elif op == OP_MEMBER_DECORATE and args[2] == DEC_OFFSET:
            offsets[(args[0], args[1])] = args[3]
        i += count
    out = {"bindings": {}, "sets": set(), "push": [], "local_size": local}
    for var, ptr, sc in variables:
        pointee = pointers[ptr][1]
        if sc == SC_PUSH_CONSTANT:
            members = types[pointee][1]
            out["push"] = [(offsets[(pointee, m)], types[t]) for m, t in enumerate(members)]
        elif var in binding:
            out["bindings"][binding[var]] = names.get(pointee, "?")
            out["sets"].add(dset.get(var, 0))
    return out


def _with_includes(path) -> str:
    """The shader's text with its local #includes spliced in (two kernels share gs_raster.glsl)."""
    return re.sub(r'#include "([^"]+)"', lambda m: _with_includes(path.parent / m.group(1)), path.read_text())


@pytest.mark.parametrize("name", sorted(KERNELS))
def test_kernel_table_matches_the_spirv(name):
    k = KERNELS[name]
    r = reflect(SPV / f"{name}.spv")
    assert r["sets"] <= {0}
    # glslc -O strips names: the SPIR-V gives the binding numbers, the GLSL source the block names
    # (a binding the shader never reads is dropped by the optimiser: gs_emit's DepthKey)
    assert set(r["bindings"]) <= set(range(len(k.buffers))), f"{name}: SPIR-V binds {sorted(r['bindings'])}"
    src = _with_includes(ROOT / "shaders" / f"{name}.comp")
    named = {int(b): n for b, n in re.findall(r"binding\s*=\s*(\d+)\)\s*(?:\w+\s+)*buffer\s+(\w+)", src)}
    assert named == dict(enumerate(k.buffers)), f"{name}: GLSL binds {named}, table {k.buffers}"
    assert r["push"] == [(4 * i, t) for i, (_, t) in enumerate(k.push)], f"{name}: push {r['push']} vs {k.push}"
    assert r["local_size"] == k.local_size


def test_every_shader_has_a_kernel_entry():
    assert {p.stem for p in SPV.glob("*.spv")} == set(KERNELS)


def test_constants_glsl_is_generated_from_python():
    sys.path.insert(0, str(ROOT / "scripts"))
    import build_shaders
    assert (ROOT / "shaders" / "constants.glsl").read_text() == build_shaders.constants_glsl()
    assert constants.DEPTH_KEY_BITS + constants.DEPTH_KEY_SHIFT == 31  # the distance's bits but its sign's


def test_compiled_shaders_are_current():
    # the .spv files were built from the sources (and constants.glsl) as they are now
    sys.path.insert(0, str(ROOT / "scripts"))
    import json
    import build_shaders
    record = json.loads((SPV / "sources.json").read_text())
    for comp in sorted((ROOT / "shaders").glob("*.comp")):
        assert record.get(comp.name) == build_shaders.source_hash(comp), f"{comp.name}: run scripts/build_shaders.py"


def test_push_values_are_checked_by_name():
    k = KERNELS["probe_integrate"]
    assert len(k.pack({"n": 4, "m": 2})) == k.push_size == 8
    with pytest.raises(TypeError, match="missing"):
        k.pack({"n": 4})
    with pytest.raises(TypeError, match="unknown"):
        k.pack({"n": 4, "m": 2, "k": 1})
