"""The glsl backend's storage interface has one definition, shaders/interface.glsl, which the kernels include and
gbviewer.render.glsl.interface reads at import; these tests tie it, and the GLSL structs, to the C++ structs.

- interface.glsl holds only definitions (the strict reader), its counter slots are distinct and inside the buffer;
- every GLSL struct of common.glsl has the fields of its C++ namesake (common.h) at the same byte offsets, with the
  same size: a small C++ program prints offsetof / sizeof of each field the GLSL declares (compiled with g++ against
  native/include), so a renamed, retyped, reordered or added field fails;
- TileRect is RECT_WORDS words and OitParams' fields sit at their OIT_* components of the `oit` and `view_filter`
  uniforms;
- pack_splat / unpack_splat (kernel.glsl) store every Splat2D field but those unpack recomputes, each at the same
  place both ways, in exactly SPLAT_VEC4S vec4; pack_stage / unpack_stage (preprocess_stage.glsl) every StageSplat
  field (preprocess_stage.h) and the kept flag in STAGE_VEC4S;
- the kernels and the driver name counter slots, never number them.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from helpers import skip_or_fail

from gbviewer.render.glsl import interface as gi

REPO = Path(__file__).resolve().parents[2]
SHADERS = REPO / "shaders"
FLOATS = {"float": 1, "int": 1, "uint": 1, "vec2": 2, "vec3": 3, "vec4": 4, "ivec4": 4}
STRUCTS = ["CameraParams", "Splat2D", "TileRect", "OitParams", "StageSplat"]
STRUCT_FILES = ("common.glsl", "preprocess_stage.glsl")  # the GLSL ports of common.h and preprocess_stage.h


def _code(name: str) -> str:
    return re.sub(r"//[^\n]*", "", (SHADERS / name).read_text())


def glsl_fields(struct: str) -> list[tuple[str, int]]:
    """(name, size in 4-byte words) of the struct's fields in its GLSL file, in declaration order."""
    code = "\n".join(_code(f) for f in STRUCT_FILES)
    body = re.search(rf"struct\s+{struct}\s*\{{([^}}]*)\}}", code).group(1)
    out = []
    for decl in filter(None, (d.strip() for d in body.split(";"))):
        typ, names = decl.split(None, 1)
        for name in names.split(","):
            m = re.fullmatch(r"\s*(\w+)\s*(?:\[(\d+)\])?\s*", name)
            out.append((m.group(1), FLOATS[typ] * int(m.group(2) or 1)))
    return out


@pytest.fixture(scope="module")
def cpp_layout(tmp_path_factory) -> dict[str, dict[str, int]]:
    """{struct: {field: byte offset, "sizeof": size}} of the C++ structs, for the fields the GLSL structs declare."""
    cxx = shutil.which(os.environ.get("CXX", "g++")) or shutil.which("g++")
    if cxx is None:
        skip_or_fail("no C++ compiler (g++) on PATH")
    lines = []
    for struct in STRUCTS:
        lines.append(f'    std::printf("{struct} sizeof %zu\\n", sizeof(gbv::{struct}));')
        lines += [
            f'    std::printf("{struct} {f} %zu\\n", offsetof(gbv::{struct}, {f}));' for f, _ in glsl_fields(struct)
        ]
    includes = "".join(
        f"#include {h}\n" for h in ("<cstddef>", "<cstdio>", '"gbv/common.h"', '"gbv/preprocess_stage.h"')
    )
    src = includes + "int main() {\n" + "\n".join(lines) + "\n}\n"
    out = tmp_path_factory.mktemp("layout")
    (out / "layout.cpp").write_text(src)
    build = subprocess.run(
        [cxx, "-std=c++17", "-I", str(REPO / "native" / "include"), str(out / "layout.cpp"), "-o", str(out / "layout")],
        capture_output=True,
        text=True,
    )
    assert build.returncode == 0, f"a GLSL field has no C++ namesake:\n{build.stderr}"
    layout: dict[str, dict[str, int]] = {}
    for line in subprocess.run([str(out / "layout")], capture_output=True, text=True, check=True).stdout.splitlines():
        struct, field, value = line.split()
        layout.setdefault(struct, {})[field] = int(value)
    return layout


@pytest.mark.parametrize("struct", STRUCTS)
def test_glsl_structs_have_the_cpp_layout(cpp_layout, struct):
    offset = 0
    for field, words in glsl_fields(struct):
        got = cpp_layout[struct][field]
        assert got == offset, f"{struct}.{field}: C++ offset {got}, GLSL {offset}"
        offset += 4 * words
    assert cpp_layout[struct]["sizeof"] == offset, f"{struct}: C++ has fields the GLSL struct lacks"


def test_rect_and_oit_records_match_the_cpp_structs(cpp_layout):
    assert cpp_layout["TileRect"]["sizeof"] == gi.RECT_WORDS * gi.WORD_BYTES
    fields = [f for f, _ in glsl_fields("OitParams")]
    # the `oit` and `view_filter` vec4 uniforms and the `view_rules` vec3
    assert cpp_layout["OitParams"]["sizeof"] == 2 * gi.VEC4_BYTES + 3 * gi.WORD_BYTES
    for f in fields:
        assert getattr(gi, f"OIT_{f.upper()}") * gi.WORD_BYTES == cpp_layout["OitParams"][f], f
    values = {
        "sigma": 2.0,
        "weight_background": 3.0,
        "et_grade": 4.0,
        "depth_correct": 1.0,
        "dilation": 0.5,
        "pre_dilation": 0.25,
        "cull_lambda": 0.75,
        "compensate": 1.0,
        "dc_clamp": 1.0,
        "support": 2.5,
        "sort_radial": 1.0,
    }
    packed = (
        gi.oit_uniform(2.0, 3.0, 4.0, True)
        + gi.view_filter_uniform(0.5, 0.25, 0.75, True)
        + gi.view_rules_uniform(True, 2.5, True)
    )
    assert packed == tuple(values[f] for f in fields)


def test_interface_is_definitions_only_with_distinct_slots(tmp_path):
    values = gi.parse(SHADERS / "interface.glsl", strict=True)
    slots = {k: v for k, v in values.items() if k.startswith("TOTAL_")}
    assert len(set(slots.values())) == len(slots) >= 12, slots
    assert all(0 <= v < gi.TOTALS_SLOTS for v in slots.values())
    assert gi.NO_TOTAL < 0 and gi.TOTALS_BYTES == gi.TOTALS_SLOTS * 4
    init = gi.totals_init()
    assert init.shape == (gi.TOTALS_SLOTS,) and init[gi.TOTAL_DEPTH_MIN] == init[gi.TOTAL_CELL_DEPTH_MIN] == 0xFFFFFFFF
    assert np.count_nonzero(init) == 2
    bad = tmp_path / "bad.glsl"
    bad.write_text("const int A = 1;\nfloat f() { return 0.0; }\n")
    with pytest.raises(ValueError, match="bad.glsl:2"):
        gi.parse(bad, strict=True)
    bad.write_text("const int A = 1;\nconst uint A = 2u;\n")
    with pytest.raises(ValueError, match="A defined twice"):
        gi.parse(bad, strict=True)


def test_splat_storage_round_trips_every_field():
    """pack_splat's vec4 hold each Splat2D field at the components unpack_splat reads it from; the fields not stored
    are exactly those unpack recomputes (from stored ones or a constant)."""
    sizes = dict(glsl_fields("Splat2D"))
    code = _code("kernel.glsl")
    pack = re.findall(r"p(\d) = vec4\(([^;]*)\);", re.search(r"void pack_splat\(.*?\n\}", code, re.S).group(0))
    assert [int(i) for i, _ in pack] == list(range(gi.SPLAT_VEC4S))
    stored = {}
    for i, args in pack:
        at = 0
        for arg in args.split(","):
            field = re.fullmatch(r"\s*s\.(\w+)\s*", arg).group(1)
            stored[field] = (int(i), at, sizes[field])
            at += sizes[field]
        assert at == 4, f"pack_splat's p{i} holds {at} floats"
    unpack = re.search(r"Splat2D unpack_splat\(.*?\n\}", code, re.S).group(0)
    read, recomputed = {}, set()
    for field, expr in re.findall(r"s\.(\w+) = ([^;]*);", unpack):
        if m := re.fullmatch(r"p(\d)\.([xyzw]+)", expr):
            read[field] = (int(m.group(1)), "xyzw".index(m.group(2)[0]), len(m.group(2)))
        else:
            assert not re.search(r"\bp\d", expr), f"unpack_splat: {field} = {expr}"
            recomputed.add(field)
    assert read == stored, "pack_splat and unpack_splat disagree on where a field is stored"
    assert set(stored) | recomputed == set(sizes) and not set(stored) & recomputed


def test_stage_storage_round_trips_every_field():
    """pack_stage's vec4 hold each StageSplat field, in declaration order, where unpack_stage's constructor reads it,
    and the kept flag in the one spare component it reads back; STAGE_VEC4S vec4 in all."""
    fields = glsl_fields("StageSplat")
    code = _code("preprocess_stage.glsl")
    pack = re.findall(r"p(\d) = vec4\(([^;]*)\);", re.search(r"void pack_stage\(.*?\n\}", code, re.S).group(0))
    assert [int(i) for i, _ in pack] == list(range(gi.STAGE_VEC4S))
    stored, flag = [], []
    for i, args in pack:
        at = 0
        for arg in args.split(","):
            if m := re.fullmatch(r"\s*s\.(\w+)\s*", arg):
                stored.append((m.group(1), f"p{i}." + "xyzw"[at : at + dict(fields)[m.group(1)]]))
                at += dict(fields)[m.group(1)]
            else:
                flag += [f"p{i}.{'xyzw'[at]}"] if "kept" in arg else []
                at += 1
        assert at == 4, f"pack_stage's p{i} holds {at} floats"
    assert [f for f, _ in stored] == [f for f, _ in fields]
    unpack = re.search(r"StageSplat unpack_stage\(.*?\n\}", code, re.S).group(0)
    args = re.search(r"return StageSplat\(([^;]*)\);", unpack).group(1)
    assert [a.strip() for a in args.split(",")] == [where for _, where in stored]
    assert flag and re.search(rf"kept = {re.escape(flag[0])} != 0\.0;", unpack), flag


def test_slots_and_sizes_are_named():
    """No kernel indexes the counter buffer with a number, and the driver passes no literal byte sizes or offsets
    to its buffer reads (the names are interface.glsl's)."""
    for comp in sorted(SHADERS.glob("*.comp")):
        for index in re.findall(r"\btotals\[([^\]]+)\]", _code(comp.name)):
            assert re.fullmatch(r"TOTAL_\w+|total_slot", index.strip()), f"{comp.name}: totals[{index}]"
    for py in sorted((REPO / "gbviewer" / "render" / "glsl").glob("*.py")):
        text = re.sub(r"#[^\n]*", "", py.read_text())
        assert not re.search(r"\.read\((?:size|offset)=\d|total_slot=-?\d", text), py.name
