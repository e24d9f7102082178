"""Hostile and careless input, by class (issue 11): every case ends with exit 2, one located
error and no traceback, in bounded time and memory, before any render, and nothing is
written outside the output folder.

All cases run in ONE subprocess under a memory rlimit (RLIMIT_AS, set with
`resource.setrlimit` before the interpreter starts): a driver calls `motion`'s real
`main()` for each case in its own folder, records exit code, stderr, seconds and whether
an exception escaped, and prints the results as JSON. One process keeps ~60 cases within
seconds; a resource bomb that escaped its bound would blow the rlimit or the clock.
A hypothesis fuzz of structural YAML mutations (aliases, nesting, huge scalars) checks
in-process that loading never raises anything but a located SceneError.
"""

from __future__ import annotations

import json
import os
import resource
import struct
import subprocess
import sys
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from motion.pipeline.errors import SceneError
from motion.pipeline.presets import load_preset
from motion.pipeline.scene import load_scene

from _scenes import BASE

MEMORY_LIMIT = 2 << 30  # bytes of address space for the driver process (RLIMIT_AS)
SECONDS_PER_CASE = 15.0  # each case's own bound (most take well under a second)


def _obj(extra: str) -> str:
    """BASE with one more object (a YAML flow mapping)."""
    return BASE + f"  - {extra}\n"


def _alias_bomb(levels: int = 25) -> str:
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    for i in range(1, levels):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]")
    return "\n".join(lines) + "\n"


def _png(width: int, height: int, declared: tuple[int, int] | None = None) -> bytes:
    """A real PNG (8-bit RGB), written by hand so the fixture needs no image library;
    `declared` puts another size in its (valid) header."""
    raw = b"".join(b"\x00" + bytes([200, 100, 50]) * width for _ in range(height))
    if declared is not None:
        width, height = declared

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")


PLY_HEAD = "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\nelement face {f}\nproperty list uchar int vertex_indices\nend_header\n"


def _ply(n_declared: int, verts: np.ndarray, faces: list[list[int]]) -> bytes:
    body = verts.astype("<f4").tobytes() + b"".join(struct.pack("<B", len(f)) + np.asarray(f, "<i4").tobytes() for f in faces)
    return PLY_HEAD.format(n=n_declared, f=len(faces)).encode() + body


TRI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float64)


def _bake_json(mutate: str) -> bytes:
    """A baked-motion JSON file for BASE (3 frames, 2 samples) with one value broken."""
    frames = []
    for f in range(3):
        t = f / 24
        pose = lambda k: {"translation": [[0.0, 0.0, 0.0]] * k, "rotation": [[1.0, 0.0, 0.0, 0.0]] * k, "scale": [[1.0, 1.0, 1.0]] * k}  # noqa: E731
        at = {"objects": {"ball": {k: v[0] for k, v in pose(1).items()}}, "camera": {k: v[0] for k, v in pose(1).items()}, "camera_scalars": {"fov": 40.0}, "lights": {}, "light_scalars": {}}
        sm = {"objects": {"ball": pose(2)}, "camera": pose(2), "camera_scalars": {"fov": [40.0, 40.0]}, "lights": {}, "light_scalars": {}}
        frames.append({"frame": f, "time": t, "shutter": [t - 1 / 96, t + 1 / 96], "sample_times": [t - 1 / 96, t + 1 / 96], "at_frame": at, "samples": sm})
    doc: dict[str, Any] = {"format": "motion-bake", "version": 1, "scene": "scene", "fps": "24", "shutter": {"angle": 180.0, "position": "center"}, "samples_per_frame": 2, "frames": frames}
    ball = doc["frames"][1]["samples"]["objects"]["ball"]
    if mutate == "nan-translation":
        ball["translation"][0][0] = float("nan")
    elif mutate == "inf-scale":
        ball["scale"][1] = [float("inf"), 1.0, 1.0]
    elif mutate == "zero-quaternion":
        ball["rotation"][0] = [0.0, 0.0, 0.0, 0.0]
    elif mutate == "frame-4000-digits":
        doc["frames"][0]["frame"] = int("9" * 4000)
    elif mutate == "samples-infinity":
        doc["samples_per_frame"] = float("inf")
    elif mutate == "translation-1e39":
        ball["translation"][1][0] = 1e39
    elif mutate == "wrong-shape":
        ball["translation"] = [[0.0, 0.0]]
    elif mutate == "no-frames":
        del doc["frames"]
    return json.dumps(doc).replace("Infinity", "1e999").encode()


def _npz_bake(mutate: str) -> bytes:
    """The JSON bake of `_bake_json` as an NPZ (the layout motion bake writes), broken."""
    import io
    import tempfile

    from motion.pipeline.bake.file_format import read_baked, write_baked

    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "m.json").write_bytes(_bake_json(""))
        write_baked(read_baked(Path(tmp) / "m.json"), Path(tmp) / "m.npz")
        arrays = dict(np.load(Path(tmp) / "m.npz", allow_pickle=False))
    key = next(k for k in arrays if k.startswith("samples/") and k.endswith("/translation"))
    if mutate == "complex":
        arrays[key] = arrays[key].astype(np.complex128)
    elif mutate == "frame-inf":
        arrays["frames"] = arrays["frames"].astype(np.float64)
        arrays["frames"][0] = np.inf
    out = io.BytesIO()
    np.savez(out, **arrays)
    return out.getvalue()


def _usda(text: str) -> str:
    return "#usda 1.0\n" + text


USD_SCENE = BASE + "imports: [{file: root.usda}]\n"


def _exr(meta: dict[str, Any] | None = None, fps: Any = 24, window: tuple[int, int] | None = None) -> bytes:
    """A real 6x4 EXR frame's bytes; `fps` may be anything the header can hold (a string);
    `window` rewrites its data window's far corner in the (otherwise valid) header."""
    import tempfile
    from fractions import Fraction

    import OpenEXR

    from motion.pipeline.frame_output import write_frame

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "f.0000.exr"
        if isinstance(fps, str):
            header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, "framesPerSecond": fps}
            with OpenEXR.File(header, {"RGBA": np.full((4, 6, 4), 0.5, np.float32)}) as f:
                f.write(str(path))
        else:
            write_frame(path, np.full((4, 6, 4), 0.5, np.float32), meta or {"frame": 0}, fps=Fraction(fps))
        data = bytearray(path.read_bytes())
    if window is not None:
        at = data.find(b"dataWindow\x00box2i\x00") + len(b"dataWindow\x00box2i\x00") + 4
        data[at + 8 : at + 16] = struct.pack("<ii", *window)
    return bytes(data)


EXR = _exr()
SEQ = {f"in/a.{i:04d}.exr": EXR for i in range(4)}
DYN = BASE.replace("radius: 0.5}", "radius: 0.5, motion: {type: dynamics}}")

# (id, class, files {name: text | bytes | "<fifo>" | ("sparse", size)}, argv run in the case folder)
V = ["validate", "scene.yaml"]


def _r(*extra: str) -> list[str]:
    return ["render", "scene.yaml", "-o", "out", "--workers", "1", "--no-progress", *extra]


CASES: list[tuple[str, str, dict[str, Any], list[str]]] = [
    # --- resource bombs in YAML (scene and preset) ---
    ("alias-bomb", "yaml-bomb", {"scene.yaml": _alias_bomb() + BASE}, V),
    ("alias-bomb-preset", "yaml-bomb", {"scene.yaml": BASE, "p.yaml": _alias_bomb() + "render: {spp: 1}\n"}, [*V, "--preset", "p.yaml"]),
    ("alias-bomb-render", "yaml-bomb", {"scene.yaml": _alias_bomb() + BASE}, _r()),
    ("recursive-alias", "yaml-bomb", {"scene.yaml": "x: &a [*a]\n" + BASE}, V),
    ("recursive-alias-map", "yaml-bomb", {"scene.yaml": "x: &a {y: *a}\n" + BASE}, V),
    ("deep-sequences", "yaml-bomb", {"scene.yaml": BASE + "dynamics: " + "[" * 50000 + "]" * 50000 + "\n"}, V),
    ("deep-mappings", "yaml-bomb", {"scene.yaml": BASE + "dynamics: " + "{a: " * 5000 + "1" + "}" * 5000 + "\n"}, V),
    ("deep-block", "yaml-bomb", {"scene.yaml": BASE + "x:\n" + "".join(" " * i + "- \n" for i in range(1, 200))}, V),
    ("deep-preset", "yaml-bomb", {"scene.yaml": BASE, "p.yaml": "render: " + "[" * 20000 + "]" * 20000 + "\n"}, [*V, "--preset", "p.yaml"]),
    ("huge-int", "yaml-bomb", {"scene.yaml": BASE.replace("last: 2", "last: " + "9" * 5000)}, V),
    ("huge-int-preset", "yaml-bomb", {"scene.yaml": BASE, "p.yaml": "frame_count: " + "7" * 6000 + "\n"}, [*V, "--preset", "p.yaml"]),
    ("huge-int-hex", "yaml-bomb", {"scene.yaml": BASE.replace("variant: scalar_rgb", "variant: scalar_rgb, seed: 0x" + "f" * 4000)}, V),
    ("huge-float", "yaml-bomb", {"scene.yaml": BASE.replace("radius: 0.5", "radius: 1e99999")}, V),
    ("huge-file", "yaml-bomb", {"scene.yaml": ("sparse", 64 << 20)}, V),
    ("dev-zero", "yaml-bomb", {}, ["validate", "/dev/zero"]),
    ("dev-zero-render", "yaml-bomb", {}, ["render", "/dev/zero", "-o", "out"]),
    ("fifo", "yaml-bomb", {"scene.yaml": "<fifo>"}, V),
    ("preset-fifo", "yaml-bomb", {"scene.yaml": BASE, "p.yaml": "<fifo>"}, [*V, "--preset", "p.yaml"]),
    ("not-utf8", "yaml-bomb", {"scene.yaml": b"camera: {}\n\xff\xfe\x00bad"}, V),
    ("nul-bytes", "yaml-bomb", {"scene.yaml": BASE + "\x00\x00\n"}, V),
    # --- sizes without limits ---
    ("frames-1e11", "sizes", {"scene.yaml": BASE.replace("last: 2", "last: 999999")}, _r("--frames", "0-100000000000")),
    ("frames-1e11-bake", "sizes", {"scene.yaml": BASE}, ["bake", "scene.yaml", "-o", "out/m.json", "--frames", "0-100000000000"]),
    ("frames-many-parts", "sizes", {"scene.yaml": BASE.replace("last: 2", "last: 999999")}, _r("--frames", ",".join(["0-999999"] * 3))),
    ("frames-digits", "sizes", {"scene.yaml": BASE}, _r("--frames", "1" * 5000)),
    ("timeline-1e11", "sizes", {"scene.yaml": BASE.replace("last: 2", "last: 100000000000")}, V),
    ("timeline-long", "sizes", {"scene.yaml": BASE.replace("last: 2", "last: 5000000")}, V),
    ("particles-1e21", "sizes", {"scene.yaml": _obj("{name: p, shape: particles, emitter: {rate: 1e21, lifetime: 1e10, max_count: 10000000}}")}, V),
    ("particles-rate-1e300", "sizes", {"scene.yaml": _obj("{name: p, shape: particles, emitter: {rate: 1e300, lifetime: 10, max_count: 5000000}}")}, _r()),
    ("particle-steps", "sizes", {"scene.yaml": BASE.replace("last: 2", "last: 100000") + "  - {name: p, shape: particles, emitter: {rate: 100000, lifetime: 10, max_count: 1000000}}\n"}, V),
    ("particle-steps-bake", "sizes", {"scene.yaml": BASE.replace("last: 2", "last: 2000") + "  - {name: p, shape: particles, emitter: {rate: 100000, max_count: 1000000}}\n"}, ["bake", "scene.yaml", "-o", "out/m.npz"]),
    ("particle-bake-budget", "sizes", {"scene.yaml": BASE.replace("last: 2", "last: 47") + "  - {name: p, shape: particles, emitter: {rate: 10000000, max_count: 1000000}}\n"}, ["bake", "scene.yaml", "-o", "out/m.npz"]),
    ("particle-render-budget", "sizes", {"scene.yaml": BASE.replace("last: 2", "last: 47") + "  - {name: p, shape: particles, emitter: {rate: 10000000, max_count: 1000000}}\n"}, _r()),
    ("sim-steps", "sizes", {"scene.yaml": _obj("{name: b, shape: sphere, motion: {type: dynamics}}") + "dynamics: {step: 1e-12}\n"}, V),
    ("workers-1e6", "sizes", {"scene.yaml": BASE}, _r("--workers", "1000000")),
    # --- problems found only at render time ---
    ("fps-tiny", "render-time", {"scene.yaml": BASE.replace("fps: 24", "fps: '1/" + "9" * 400 + "'")}, V),
    ("fps-huge", "render-time", {"scene.yaml": BASE.replace("fps: 24", "fps: '" + "9" * 400 + "/1'")}, _r()),
    ("fps-1e-9", "render-time", {"scene.yaml": BASE.replace("fps: 24", "fps: 1e-9")}, V),
    ("fps-inf", "render-time", {"scene.yaml": BASE.replace("fps: 24", "fps: .inf")}, V),
    ("fps-1e6", "render-time", {"scene.yaml": BASE.replace("fps: 24", "fps: 1000000")}, _r()),
    ("shutter-1e-300", "render-time", {"scene.yaml": BASE.replace("look_at: [0, 0, 0]}", "look_at: [0, 0, 0], shutter: {angle: 1e-300}}")}, _r()),
    ("mesh-garbage", "render-time", {"scene.yaml": _obj("{name: m, shape: mesh, file: m.obj}"), "m.obj": b"\x00\x01garbage\xff" * 50}, _r()),
    ("mesh-empty", "render-time", {"scene.yaml": _obj("{name: m, shape: mesh, file: m.obj}"), "m.obj": ""}, V),
    ("mesh-nan", "render-time", {"scene.yaml": _obj("{name: m, shape: mesh, file: m.obj}"), "m.obj": "v 0 0 0\nv nan 1 0\nv 1 0 0\nf 1 2 3\n"}, _r()),
    ("mesh-inf", "render-time", {"scene.yaml": _obj("{name: m, shape: mesh, file: m.obj}"), "m.obj": "v 0 0 0\nv 1e999 1 0\nv 1 0 0\nf 1 2 3\n"}, V),
    ("mesh-bad-index", "render-time", {"scene.yaml": _obj("{name: m, shape: mesh, file: m.obj}"), "m.obj": "v 0 0 0\nv 0 1 0\nv 1 0 0\nf 1 2 4\n"}, V),
    ("mesh-short-vertex", "render-time", {"scene.yaml": _obj("{name: m, shape: mesh, file: m.obj}"), "m.obj": "v 0 0\nv 0 1 0\nv 1 0 0\nf 1 2 3\n"}, V),
    ("mesh-ply-truncated", "render-time", {"scene.yaml": _obj("{name: m, shape: mesh, file: m.ply}"), "m.ply": _ply(3, TRI, [[0, 1, 2]])[:-7]}, _r()),
    ("mesh-ply-count-lies", "render-time", {"scene.yaml": _obj("{name: m, shape: mesh, file: m.ply}"), "m.ply": _ply(1000000, TRI, [[0, 1, 2]])}, V),
    ("mesh-ply-nan", "render-time", {"scene.yaml": _obj("{name: m, shape: mesh, file: m.ply}"), "m.ply": _ply(3, np.array([[0, 0, 0], [np.nan, 0, 0], [0, 1, 0]]), [[0, 1, 2]])}, V),
    ("mesh-ply-index", "render-time", {"scene.yaml": _obj("{name: m, shape: mesh, file: m.ply}"), "m.ply": _ply(3, TRI, [[0, 1, 7]])}, V),
    ("mesh-is-folder", "render-time", {"scene.yaml": _obj("{name: m, shape: mesh, file: m.obj}"), "m.obj/x": "v 0 0 0\n"}, V),
    ("texture-not-image", "render-time", {"scene.yaml": BASE.replace("radius: 0.5}", "radius: 0.5, material: t}") + "materials: [{name: t, type: diffuse, color: {file: t.png}}]\n", "t.png": "hello"}, _r()),
    ("texture-empty", "render-time", {"scene.yaml": BASE.replace("radius: 0.5}", "radius: 0.5, material: t}") + "materials: [{name: t, type: diffuse, color: {file: t.png}}]\n", "t.png": b""}, V),
    ("texture-truncated", "render-time", {"scene.yaml": BASE.replace("radius: 0.5}", "radius: 0.5, material: t}") + "materials: [{name: t, type: principled, color: {file: t.png}}]\n", "t.png": _png(64, 64)[:-40]}, V),
    ("texture-unknown-format", "render-time", {"scene.yaml": BASE.replace("radius: 0.5}", "radius: 0.5, material: t}") + "materials: [{name: t, type: diffuse, color: {file: t.tif}}]\n", "t.tif": _png(4, 4)}, V),
    ("envmap-not-image", "render-time", {"scene.yaml": BASE.replace("{type: constant, radiance: 0.5}", "{type: envmap, file: sky.exr}"), "sky.exr": "not an exr"}, _r()),
    ("envmap-hdr-truncated", "render-time", {"scene.yaml": BASE.replace("{type: constant, radiance: 0.5}", "{type: envmap, file: sky.hdr}"), "sky.hdr": b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 64 +X 64\n" + b"\x80" * 100}, V),
    ("envmap-pfm-nan", "render-time", {"scene.yaml": BASE.replace("{type: constant, radiance: 0.5}", "{type: envmap, file: sky.pfm}"), "sky.pfm": b"PF\n2 1\n-1.0\n" + np.array([1, 1, 1, np.nan, 0, 0], "<f4").tobytes()}, V),
    ("envmap-huge-header", "render-time", {"scene.yaml": BASE.replace("{type: constant, radiance: 0.5}", "{type: envmap, file: sky.png}"), "sky.png": _png(1, 1, declared=(100000, 100000))}, V),
    # --- outputs outside the output folder ---
    ("pattern-dotdot", "output", {"scene.yaml": BASE + "output: {filename: '../escaped/{name}.####.exr'}\n"}, _r()),
    ("pattern-absolute", "output", {"scene.yaml": BASE + "output: {filename: '/tmp/motion-escaped/{name}.####.exr'}\n"}, _r()),
    ("pattern-inner-dotdot", "output", {"scene.yaml": BASE + "output: {filename: 'a/../../b/{name}.####.exr'}\n"}, _r()),
    ("pattern-preset", "output", {"scene.yaml": BASE, "p.yaml": "output: {filename: '../../{name}.####.exr'}\n"}, _r("--preset", "p.yaml")),
    # --- non-finite values ---
    ("ballistic-overflow", "non-finite", {"scene.yaml": BASE.replace("last: 2", "last: 60").replace("radius: 0.5}", "radius: 0.5, motion: {type: procedural, generators: [{type: ballistic, v0: [0, 0, 0], a: [1e308, 0, 0]}]}}")}, _r()),
    ("ballistic-overflow-bake", "non-finite", {"scene.yaml": BASE.replace("last: 2", "last: 60").replace("radius: 0.5}", "radius: 0.5, motion: {type: procedural, generators: [{type: ballistic, v0: [1e308, 0, 0], a: [0, 0, 0]}]}}")}, ["bake", "scene.yaml", "-o", "out/m.json"]),
    ("expression-overflow", "non-finite", {"scene.yaml": BASE.replace("radius: 0.5}", "radius: 0.5, motion: {type: procedural, channels: {scale: '10**60 * 10**60 * 10**60 * 10**60 * 10**60 * 10**60'}}}")}, _r()),
    ("bake-nan", "non-finite", {"scene.yaml": BASE, "m.json": _bake_json("nan-translation")}, _r("--motion", "m.json")),
    ("bake-inf-scale", "non-finite", {"scene.yaml": BASE, "m.json": _bake_json("inf-scale")}, _r("--motion", "m.json")),
    ("bake-zero-quaternion", "non-finite", {"scene.yaml": BASE, "m.json": _bake_json("zero-quaternion")}, _r("--motion", "m.json")),
    ("bake-wrong-shape", "non-finite", {"scene.yaml": BASE, "m.json": _bake_json("wrong-shape")}, _r("--motion", "m.json")),
    # --- misreported files ---
    ("motion-empty-json", "misreported", {"scene.yaml": BASE, "m.json": b""}, _r("--motion", "m.json")),
    ("motion-empty-npz", "misreported", {"scene.yaml": BASE, "m.npz": b""}, _r("--motion", "m.npz")),
    ("motion-text", "misreported", {"scene.yaml": BASE, "m.npz": "hello\n"}, _r("--motion", "m.npz")),
    ("motion-json-list", "misreported", {"scene.yaml": BASE, "m.json": "[1, 2, 3]"}, _r("--motion", "m.json")),
    ("motion-json-deep", "misreported", {"scene.yaml": BASE, "m.json": "[" * 100000 + "]" * 100000}, _r("--motion", "m.json")),
    ("motion-no-frames", "misreported", {"scene.yaml": BASE, "m.json": _bake_json("no-frames")}, _r("--motion", "m.json")),
    ("motion-dev-zero", "misreported", {"scene.yaml": BASE}, _r("--motion", "/dev/zero")),
    ("motion-folder", "misreported", {"scene.yaml": BASE, "m.json/x": "1"}, _r("--motion", "m.json")),
    ("report-unwritable", "misreported", {"scene.yaml": BASE, "afile": "x"}, _r("--report", "afile/report.json")),
    ("output-unwritable", "misreported", {"scene.yaml": BASE, "afile": "x"}, ["render", "scene.yaml", "-o", "afile/out", "--no-progress"]),
    # --- round 3 (issue 24): the options of the commands beside `render` ---
    ("export-exposure-5000", "options", SEQ, ["export", "in", "-o", "out/png", "--exposure", "5000"]),
    ("export-exposure-nan", "options", SEQ, ["export", "in", "-o", "out/png", "--exposure", "nan"]),
    ("view-exposure-inf", "options", SEQ, ["view", "in", "-o", "out/v/index.html", "--exposure", "inf"]),
    ("sheet-exposure-nan", "options", SEQ, ["contact-sheet", "in", "-o", "out/c.png", "--exposure", "nan"]),
    ("deliver-exposure-nan", "options", {"scene.yaml": BASE}, _r("--deliver", "contact", "--exposure", "nan")),
    ("sheet-columns-negative", "options", SEQ, ["contact-sheet", "in", "-o", "out/c.png", "--columns", "-1"]),
    ("sheet-columns-1e9", "options", SEQ, ["contact-sheet", "in", "-o", "out/c.png", "--columns", "1000000000"]),
    ("sheet-width-1e9", "options", SEQ, ["contact-sheet", "in", "-o", "out/c.png", "--width", "1000000000"]),
    ("telecine-film-speed-0.3", "options", SEQ, ["telecine", "in", "-o", "out/t", "--film-speed", "0.3"]),
    ("telecine-film-speed-1e9", "options", SEQ, ["telecine", "in", "-o", "out/t", "--film-speed", "1e9"]),
    ("plot-until-1e12", "options", {"scene.yaml": DYN}, ["plot", "scene.yaml", "-o", "out/p.png", "--until", "1e12"]),
    ("plot-until-nan", "options", {"scene.yaml": DYN}, ["plot", "scene.yaml", "-o", "out/p.png", "--until", "nan"]),
    ("exr-fps-string", "options", {f"in/a.{i:04d}.exr": _exr(fps="abc") for i in range(2)}, ["contact-sheet", "in", "-o", "out/c.png"]),
    ("exr-window-1e5", "options", {"in/a.0000.exr": _exr(window=(99999, 99999))}, ["export", "in", "-o", "out/png"]),
    ("exr-window-1e5-sheet", "options", {"in/a.0000.exr": EXR, "in/a.0001.exr": _exr(window=(99999, 99999))}, ["contact-sheet", "in", "-o", "out/c.png"]),
    ("inverse-field-source-abc", "options", {f"in/a.{i:04d}.exr": _exr({"frame": i, "topFieldSource": "abc", "bottomFieldSource": "abc"}, fps=30) for i in range(5)},
     ["telecine", "in", "-o", "out/t", "--inverse"]),
    # --- round 3: a scheduler address that is not one (probed in seconds, before the bake) ---
    ("scheduler-scheme", "scheduler", {"scene.yaml": BASE}, _r("--scheduler", "garbage://host:1")),
    ("scheduler-port-text", "scheduler", {"scene.yaml": BASE}, _r("--scheduler", "localhost:abc")),
    ("scheduler-port-range", "scheduler", {"scene.yaml": BASE}, _r("--scheduler", "tcp://127.0.0.1:99999")),
    ("scheduler-file-not-json", "scheduler", {"scene.yaml": BASE, "s.json": "not json"}, _r("--scheduler", "s.json")),
    ("scheduler-file-no-address", "scheduler", {"scene.yaml": BASE, "s.json": '{"id": 1}'}, _r("--scheduler", "s.json")),
    ("scheduler-refused", "scheduler", {"scene.yaml": BASE}, _r("--scheduler", "tcp://127.0.0.1:1", "--dry-run")),
    # --- round 3: links pre-placed inside the output folder lead nothing out of it ---
    ("link-frames-subfolder", "links", {"scene.yaml": BASE + "output: {filename: 'sub/{name}.####.exr'}\n", "elsewhere/keep": "", "out/sub": ("link", "../elsewhere")}, _r()),
    ("link-claims-folder", "links", {"scene.yaml": BASE, "elsewhere/keep": "", "out/.motion-claims": ("link", "../elsewhere")}, _r()),
    ("link-claims-subfolder", "links", {"scene.yaml": BASE + "output: {filename: 'sub/{name}.####.exr'}\n", "elsewhere/keep": "", "out/sub/.motion-claims": ("link", "../../elsewhere")}, _r()),
    ("link-deliver", "links", {"scene.yaml": BASE, "elsewhere/keep": "", "out/deliver": ("link", "../elsewhere")}, _r("--deliver", "contact")),
    # --- round 3: numbers finite in float64 that the renderer (float32) or a half EXR cannot hold ---
    ("range-translate-1e39", "range", {"scene.yaml": BASE.replace("radius: 0.5}", "radius: 0.5, transform: {translate: [1e39, 0, 0]}}")}, _r()),
    ("range-scale-1e39", "range", {"scene.yaml": BASE.replace("radius: 0.5}", "radius: 0.5, transform: {scale: 1.0e39}}")}, V),
    ("range-radiance-1e39", "range", {"scene.yaml": BASE.replace("radiance: 0.5", "radiance: 1.0e39")}, _r()),
    ("range-radiance-half", "range", {"scene.yaml": BASE.replace("radius: 0.5}", "radius: 0.5, emission: {radiance: 100000}}")}, _r()),
    ("range-expression-1e48", "range", {"scene.yaml": BASE.replace("radius: 0.5}", "radius: 0.5, motion: {type: procedural, channels: {translate: ['10**24 * 10**24 * (t + 1)', '0', '0']}}}")}, _r()),
    ("range-expression-1e179-bake", "range", {"scene.yaml": BASE.replace("radius: 0.5}", "radius: 0.5, motion: {type: procedural, channels: {translate: ['10**179 * (t + 1)', '0', '0']}}}")}, ["bake", "scene.yaml", "-o", "out/m.json"]),
    ("range-obj-vertex-1e39", "range", {"scene.yaml": _obj("{name: m, shape: mesh, file: m.obj}"), "m.obj": "v 0 0 0\nv 1e39 1 0\nv 1 0 0\nf 1 2 3\n"}, V),
    ("range-bake-json-1e39", "range", {"scene.yaml": BASE, "m.json": _bake_json("translation-1e39")}, _r("--motion", "m.json")),
    # --- round 3: degenerate but valid input is refused at once (or renders: tests below) ---
    ("ik-zero-length-bones", "degenerate", {"scene.yaml": BASE.replace("  - {name: ball, shape: sphere, radius: 0.5}\n", "  - {name: a, shape: sphere, radius: 0.1}\n  - {name: b, shape: sphere, radius: 0.1, parent: a}\n"
                                                                       "  - {name: c, shape: sphere, radius: 0.1, parent: b}\n  - {name: tgt, shape: sphere, radius: 0.1, transform: {translate: [1, 0, 0]}}\n")
                                                          + "ik: [{chain: [a, b, c], target: tgt}]\n"}, _r()),
    # --- round 3: sizes of imports, bakes, flocks, checked before allocation ---
    ("keys-300k", "sizes-3", {"scene.yaml": BASE.replace("radius: 0.5}", "radius: 0.5, motion: {type: keyframes, channels: {translate: {keys: ["
                                                          + ",".join(f"{{time: {i}e-6, value: [0, 0, 0]}}" for i in range(300_000)) + "]}}}}")}, V),
    ("flock-160k-agents", "sizes-3", {"scene.yaml": _obj("{name: birds, shape: cube, size: 0.1, deform: {type: flock, count: 160000}}").replace("last: 2", "last: 1200")}, _r()),
    ("texture-30000-squared", "sizes-3", {"scene.yaml": BASE.replace("radius: 0.5}", "radius: 0.5, material: t}") + "materials: [{name: t, type: diffuse, color: {file: t.png}}]\n",
                                          "t.png": _png(1, 1, declared=(30000, 30000))}, _r()),
    ("plan-radius-200m", "sizes-3", {"scene.yaml": _obj("{name: bot, shape: sphere, radius: 0.2, motion: {type: plan, grid: {from_scene: true, cell: 2, origin: [-500, -500], size: [1000, 1000]}, "
                                                     "start: [-400, 0.2, 0], goal: [400, 0.2, 0], radius: 200, speed: 1}}")}, _r("--dry-run")),
    ("gltf-300k-nodes", "sizes-3", {"scene.yaml": BASE + "imports: [{file: n.gltf}]\n",
                                    "n.gltf": json.dumps({"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"name": f"n{i}"} for i in range(300_000)]})}, V),
    ("gltf-accessor-44m", "sizes-3", {"scene.yaml": BASE + "imports: [{file: a.gltf}]\n",
                                      "a.gltf": json.dumps({"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
                                                            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
                                                            "accessors": [{"componentType": 5126, "type": "VEC3", "count": 44_000_000}]})}, V),
    # --- round 3: USD layers resolve inside the scene's folder, regular files, no cycles ---
    ("usd-sublayer-self", "usd-layers", {"scene.yaml": USD_SCENE, "root.usda": _usda('(\n    subLayers = [@./root.usda@]\n)\ndef Xform "a" {}\n')}, V),
    ("usd-sublayer-dev-zero", "usd-layers", {"scene.yaml": USD_SCENE, "root.usda": _usda('(\n    subLayers = [@/dev/zero@]\n)\ndef Xform "a" {}\n')}, V),
    ("usd-sublayer-fifo", "usd-layers", {"scene.yaml": USD_SCENE, "root.usda": _usda('(\n    subLayers = [@./f.usda@]\n)\ndef Xform "a" {}\n'), "f.usda": "<fifo>"}, V),
    ("usd-reference-outside", "usd-layers", {"scene.yaml": USD_SCENE, "root.usda": _usda('def Xform "a" (\n    references = @/etc/hostname@</x>\n) {}\n')}, V),
    ("usd-cycle-two", "usd-layers", {"scene.yaml": USD_SCENE, "root.usda": _usda('(\n    subLayers = [@./b.usda@]\n)\n'), "b.usda": _usda('(\n    subLayers = [@./root.usda@]\n)\n')}, V),
    # --- round 3: malformed records in bake files and imports ---
    ("bake-json-frame-4000-digits", "malformed", {"scene.yaml": BASE, "m.json": _bake_json("frame-4000-digits")}, _r("--motion", "m.json")),
    ("bake-json-samples-infinity", "malformed", {"scene.yaml": BASE, "m.json": _bake_json("samples-infinity")}, _r("--motion", "m.json")),
    ("bake-npz-complex", "malformed", {"scene.yaml": BASE, "m.npz": _npz_bake("complex")}, _r("--motion", "m.npz")),
    ("bake-npz-frame-inf", "malformed", {"scene.yaml": BASE, "m.npz": _npz_bake("frame-inf")}, _r("--motion", "m.npz")),
    ("gltf-json-deep", "malformed", {"scene.yaml": BASE + "imports: [{file: d.gltf}]\n", "d.gltf": '{"asset": {"version": "2.0"}, "extras": ' + "[" * 100000 + "]" * 100000 + "}"}, V),
    ("telecine-pattern-20000", "malformed", SEQ, ["telecine", "in", "-o", "out/t", "--pattern", "23" * 10000]),
    ("link-deliver-check", "links", {"scene.yaml": BASE, "elsewhere/keep": "", "out/deliver": ("link", "../elsewhere")}, ["render", "scene.yaml", "-o", "out", "--check", "--deliver", "contact"]),
]

DRIVER = r"""
import contextlib, io, json, os, signal, sys, time, traceback
from motion.cli.main import main
cases, limit = json.loads(sys.stdin.read())
out = []
root = os.getcwd()

def overtime(signum, frame):
    raise TimeoutError(f"still running after {limit} s")

signal.signal(signal.SIGALRM, overtime)
for case_id, argv in cases:
    os.chdir(os.path.join(root, case_id))
    err = io.StringIO()
    t0 = time.perf_counter()
    escaped = None
    signal.alarm(int(limit))  # a case that hangs (a FIFO, an endless loop) fails alone
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = main(argv)
    except BaseException as exc:
        code, escaped = None, traceback.format_exc()
    signal.alarm(0)
    out.append({"id": case_id, "code": code, "stderr": err.getvalue(), "seconds": time.perf_counter() - t0, "escaped": escaped})
    os.chdir(root)
print(json.dumps(out))
"""


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def _files(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, set[str], set[str], dict[str, dict[str, Any]]]:
    root = tmp_path_factory.mktemp("hostile")
    work = root / "cases"
    for case_id, _, files, _ in CASES:
        folder = work / case_id
        folder.mkdir(parents=True)
        for name, content in files.items():
            path = folder / name
            path.parent.mkdir(parents=True, exist_ok=True)
            if content == "<fifo>":
                os.mkfifo(path)
            elif isinstance(content, tuple) and content[0] == "link":
                path.symlink_to(content[1])
            elif isinstance(content, tuple):
                with open(path, "wb") as fh:
                    fh.truncate(content[1])  # sparse: size without disk
            else:
                path.write_bytes(content if isinstance(content, bytes) else content.encode())
    before = _files(root)
    env = {**os.environ, "MOTION_CACHE_DIR": str(root / "cache"), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.run(
        [sys.executable, "-c", DRIVER],
        input=json.dumps([[(c[0], c[3]) for c in CASES], SECONDS_PER_CASE]),
        capture_output=True,
        text=True,
        cwd=work,
        env=env,
        preexec_fn=_limit_memory,
        timeout=SECONDS_PER_CASE * len(CASES) + 60,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    rows = {r["id"]: r for r in json.loads(proc.stdout.strip().splitlines()[-1])}
    return root, before, _files(root), rows


@pytest.mark.parametrize("case_id,kind", [(c[0], c[1]) for c in CASES], ids=[c[0] for c in CASES])
def test_hostile_case_is_a_clean_error(results: tuple[Path, set[str], set[str], dict[str, dict[str, Any]]], case_id: str, kind: str) -> None:
    root, before, after, rows = results
    row = rows[case_id]
    assert row["escaped"] is None, f"{case_id}: an exception escaped main():\n{row['escaped']}"
    assert row["code"] == 2, f"{case_id}: exit {row['code']}, stderr:\n{row['stderr'][-2000:]}"
    lines = [line for line in row["stderr"].splitlines() if line.strip()]
    assert lines, f"{case_id}: no error message"
    assert "Traceback" not in row["stderr"]
    assert len(lines) <= 2, f"{case_id}: expected one error line, got:\n{row['stderr']}"
    assert all(len(line) < 600 for line in lines), f"{case_id}: an error line is too long"
    assert row["seconds"] < SECONDS_PER_CASE, f"{case_id}: took {row['seconds']:.1f}s"
    # nothing written outside this case's output folder (nor anywhere by `validate`)
    new = sorted(p for p in after - before if p.startswith(f"cases/{case_id}/") or not p.startswith("cases/"))
    allowed = f"cases/{case_id}/out"
    stray = [p for p in new if not (p == allowed or p.startswith(allowed + "/")) and not p.startswith("cache")]
    assert not stray, f"{case_id}: wrote outside the output folder: {stray}"
    assert not any(f.endswith(".exr") for f in new), f"{case_id}: rendered frames before failing: {new}"


def test_every_class_is_covered() -> None:
    kinds = {c[1] for c in CASES}
    assert kinds == {"yaml-bomb", "sizes", "render-time", "output", "non-finite", "misreported", "options", "scheduler", "links", "range", "degenerate", "usd-layers", "malformed", "sizes-3"}
    assert not Path("/tmp/motion-escaped").exists()


def test_located_errors_point_at_the_field(results: tuple[Path, set[str], set[str], dict[str, dict[str, Any]]]) -> None:
    """A sample of classes: the line is FILE:LINE:COL: yaml.path: message."""
    rows = results[3]
    expect = {
        "alias-bomb": ("scene.yaml:", "aliases expand"),
        "deep-sequences": ("scene.yaml:", "nesting deeper than"),
        "huge-int": ("scene.yaml:", "integer literal of 5000 characters"),
        "timeline-1e11": ("scene.yaml:1:", "timeline.last"),
        "particles-1e21": ("scene.yaml:", "objects[1].emitter"),
        "mesh-nan": ("scene.yaml:7:", "objects[1].file: mesh file m.obj: line 2: vertex 1 is not finite"),
        "mesh-ply-truncated": ("scene.yaml:7:", "truncated"),
        "texture-not-image": ("scene.yaml:", "materials[0].color.file"),
        "pattern-dotdot": ("scene.yaml:", "output.filename"),
        "pattern-preset": ("p.yaml:1:", "output.filename"),
        "particle-bake-budget": ("scene.yaml:", "particle positions; the limit is"),
        "envmap-huge-header": ("scene.yaml:", "over the limit of"),
        "frames-1e11": ("--frames", "limited to"),
        "ballistic-overflow": ("scene.yaml:6:", "generators[0].a[0]: 1e+308 is beyond what the renderer holds (float32"),
        "ballistic-overflow-bake": ("scene.yaml:6:", "generators[0].v0[0]: 1e+308 is beyond what the renderer holds"),
        "range-translate-1e39": ("scene.yaml:6:", "objects[0].transform.translate[0]: 1e+39 is beyond what the renderer holds"),
        "range-radiance-half": ("scene.yaml:6:", "objects[0].emission.radiance: radiance 100000 is beyond what a half-float EXR holds"),
        "range-expression-1e48": ("scene.yaml:6:", "objects[0].motion.channels.translate[0]: expression '10**24 * 10**24 * (t + 1)' is 1e+48 at frame 0"),
        "range-bake-json-1e39": ("m.json", "object 'ball': translation is not finite in the renderer's float32"),
        "ik-zero-length-bones": ("scene.yaml:", "ik[0].chain[1]: the bone a -> b has no length"),
        "plan-radius-200m": ("scene.yaml:", "objects[1].motion.radius: bot: an agent of radius 200.0 m"),
        "bake-zero-quaternion": ("m.json", "object 'ball': rotation is not a unit quaternion"),
        "motion-empty-json": ("m.json", "empty"),
        "report-unwritable": ("--report", "cannot write"),
    }
    for case_id, (where, what) in expect.items():
        text = rows[case_id]["stderr"]
        assert where in text and what in text, f"{case_id}: {text}"


# --- fuzz: structural YAML mutations never produce anything but a located SceneError ------

_SCALARS = st.one_of(
    st.integers(min_value=-(10**40), max_value=10**40).map(str),
    st.sampled_from(["1e999", "-.inf", ".nan", "0x" + "f" * 60, "9" * 200, "~", "''", "!!binary aGVsbG8=", "!!python/object:os.system ls", "*undefined", "&x 1", "1:2:3:4:5:6"]),
    st.text(alphabet="abcxyz012 ", max_size=20).map(lambda s: repr(s)),
)


@st.composite
def _mutated(draw: st.DrawFn) -> str:
    lines = BASE.splitlines()
    kind = draw(st.sampled_from(["nest", "alias", "scalar", "anchor-chain", "duplicate", "indent"]))
    i = draw(st.integers(min_value=0, max_value=len(lines) - 1))
    depth = draw(st.integers(min_value=1, max_value=200))
    if kind == "nest":
        opener = draw(st.sampled_from(["[", "{a: "]))
        closer = "]" if opener == "[" else "}"
        key = lines[i].split(":")[0] if ":" in lines[i] and not lines[i].startswith(" ") else "timeline"
        lines[i] = f"{key}: " + opener * depth + "1" + closer * depth
    elif kind == "alias":
        width = draw(st.integers(min_value=2, max_value=12))
        levels = draw(st.integers(min_value=1, max_value=12))
        head = ["b0: &b0 [1, 2]"] + [f"b{k}: &b{k} [" + ", ".join([f"*b{k - 1}"] * width) + "]" for k in range(1, levels)]
        lines = head + lines
    elif kind == "scalar":
        lines[i] = lines[i].replace(draw(st.sampled_from(["24", "0.5", "5", "1", "2", "16", "0"])), draw(_SCALARS), 1)
    elif kind == "anchor-chain":
        lines.insert(0, "z: &z " + "[" * min(depth, 80) + "*z" + "]" * min(depth, 80))
    elif kind == "duplicate":
        lines.append(lines[i])
    else:
        lines[i] = " " * depth + lines[i]
    return "\n".join(lines) + "\n"


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(text=_mutated())
def test_fuzz_structural_yaml_mutations(tmp_path: Path, text: str) -> None:
    scene = tmp_path / "fuzz.yaml"
    scene.write_text(text)
    try:
        load_scene(scene)
    except SceneError as err:
        for problem in err.problems:
            assert problem.file == str(scene) and problem.message
    preset = tmp_path / "fuzz-preset.yaml"
    preset.write_text(text)
    try:
        load_preset(str(preset))
    except SceneError as err:
        assert err.problems


# --- malformed records, the range policy, degenerate input refused
# at validation. Each case runs motion's real main() in process (none is a
# resource bomb) and must end in exit 2, one line naming the file and what is wrong, and
# no frame written.


def _bake_npz(tmp: Path, mutate: Any) -> Path:
    """A real NPZ bake of BASE (`motion bake`), with `mutate(arrays)` applied to its arrays."""
    from motion.cli.main import main as motion_main

    (tmp / "scene.yaml").write_text(BASE)
    assert motion_main(["-q", "bake", str(tmp / "scene.yaml"), "-o", str(tmp / "good.npz")]) == 0
    with np.load(tmp / "good.npz") as z:
        arrays = {k: z[k].copy() for k in z.files}
    mutate(arrays)
    path = tmp / "m.npz"
    np.savez(path, **arrays)
    return path


def _gltf_triangle(path: Path, sparse_indices: np.ndarray | None = None) -> Path:
    """A one-triangle glTF; `sparse_indices` (their dtype kept) move those vertices by sparse values."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
    from gltf_writer import GltfBuilder

    b = GltfBuilder()
    pos = b.accessor(TRI, bounds=True)
    if sparse_indices is not None:
        kinds = {np.dtype("int16"): 5122, np.dtype("uint16"): 5123, np.dtype("int8"): 5120}
        b.gltf["accessors"][pos]["sparse"] = {"count": len(sparse_indices),
                                              "indices": {"bufferView": b.view(sparse_indices.tobytes()), "componentType": kinds[sparse_indices.dtype]},
                                              "values": {"bufferView": b.view(np.full((len(sparse_indices), 3), 5.0, np.float32).tobytes())}}
    b.gltf["meshes"].append({"name": "m", "primitives": [{"attributes": {"POSITION": pos}, "indices": b.accessor(np.array([0, 1, 2]), dtype="uint16")}]})
    b.gltf["scenes"][0]["nodes"].append(b.node(name="tri", mesh=0))
    return b.save(path)


def _json_bake(tmp: Path, old: str, new: str) -> Path:
    """_bake_json's file with one piece of its text replaced (a literal JSON's own spelling)."""
    text = _bake_json("none").decode()
    assert old in text
    path = tmp / "m.json"
    path.write_text(text.replace(old, new, 1))
    return path


def _refused(tmp: Path, argv: list[str], *fragments: str, capsys: pytest.CaptureFixture[str]) -> str:
    from motion.cli.main import main as motion_main

    capsys.readouterr()
    code = motion_main(argv)
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, f"{argv}: exit {code}\n{err}"
    assert all(f in lines[0] for f in fragments), lines[0]
    assert len(lines[0]) < 400 and not list(tmp.rglob("*.exr")), lines[0]
    return lines[0]


def _render(tmp: Path, *extra: str) -> list[str]:
    return ["render", str(tmp / "scene.yaml"), "-o", str(tmp / "out"), "--workers", "1", "--no-progress", *extra]


MALFORMED_RECORDS: list[tuple[str, Any, tuple[str, ...]]] = [
    # (id, how the input is made, fragments of the one line)
    ("npz-complex-poses", lambda a: a.__setitem__("samples/objects/ball/translation", a["samples/objects/ball/translation"] + 1j), ("m.npz", "'samples/objects/ball/translation.npy' holds complex128 values")),
    ("npz-frame-inf", lambda a: a.__setitem__("frames", np.array([0.0, np.inf, 2.0])), ("m.npz", "frames[1].frame is inf, expected a whole number")),
    ("npz-frame-complex", lambda a: a.__setitem__("frames", a["frames"].astype(complex)), ("m.npz", "'frames.npy' holds complex128 values")),
    ("npz-frame-1e12", lambda a: a.__setitem__("frames", a["frames"] * 10**12), ("m.npz", "frames[1].frame is 1e+12, expected -1000000000 to 1000000000")),
    ("npz-times-complex", lambda a: a.__setitem__("times", a["times"].astype(complex)), ("m.npz", "'times.npy' holds complex128 values")),
    ("json-frame-4000-digits", ('"frame": 1,', '"frame": ' + "9" * 4000 + ","), ("m.json", "an integer of 4000 digits (at most 20)")),
    ("json-samples-infinity", ('"samples_per_frame": 2', '"samples_per_frame": Infinity'), ("m.json", "Infinity is not a finite number")),
    ("json-samples-1e9", ('"samples_per_frame": 2', '"samples_per_frame": 1000000000'), ("m.json", "samples_per_frame is 1e+09, expected 1 to 256")),
    ("json-frame-fraction", ('"frame": 1,', '"frame": 1.5,'), ("m.json", "frames[1].frame is 1.5, expected a whole number")),
    ("json-frame-bool", ('"frame": 1,', '"frame": true,'), ("m.json", "frames[1].frame is bool")),
    ("json-time-text", ('"time": 0.041666666666666664', '"time": "0.04"'), ("m.json", "frame 1 is malformed", "time is '0.04', expected a finite number")),
    ("json-pose-text", ('"translation": [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]', '"translation": [["0", "0", "0"], [0.0, 0.0, 0.0]]'), ("m.json", "expected real numbers")),
    ("gltf-sparse-index-minus-1", np.array([-1], np.int16), ("t.gltf", "sparse: bad sparse indices (componentType 5122")),
    ("gltf-sparse-index-repeated", np.array([1, 1], np.uint16), ("t.gltf", "sparse indices must strictly increase")),
]


@pytest.mark.parametrize("case", MALFORMED_RECORDS, ids=[c[0] for c in MALFORMED_RECORDS])
def test_malformed_records_are_located_refusals(tmp_path: Path, case: tuple[str, Any, tuple[str, ...]], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 24, malformed records: each was accepted (a complex pose cast to its real part,
    a fractional frame number truncated, a sparse index -1 writing the last vertex) or an
    OverflowError traceback (frame inf, samples_per_frame Infinity)."""
    case_id, make, fragments = case
    (tmp_path / "scene.yaml").write_text(BASE)
    if case_id.startswith("npz"):
        argv = _render(tmp_path, "--motion", str(_bake_npz(tmp_path, make)))
    elif case_id.startswith("json"):
        argv = _render(tmp_path, "--motion", str(_json_bake(tmp_path, *make)))
    else:
        _gltf_triangle(tmp_path / "t.gltf", make)
        (tmp_path / "scene.yaml").write_text(BASE + "imports: [{file: t.gltf}]\n")
        monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))  # the conversion is cached by content
        argv = _render(tmp_path)
    _refused(tmp_path, argv, *fragments, capsys=capsys)


def test_range_policy_covers_expressions_at_validation_seen_radiance_and_schema_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 24, numbers the renderer cannot hold: an expression channel reaching 1e48 was
    found only by the bake (`motion validate` said ok); an environment's radiance animated
    past what a half-float frame holds rendered (exit 0, pixels clamped); a number past
    float32 was reported only once the scene's other mistakes were fixed; NPZ bakes."""
    light = "{type: constant, radiance: 0.5}"
    (tmp_path / "scene.yaml").write_text(BASE.replace(light, "{type: constant, radiance: 0.5, motion: {type: procedural, scalars: {radiance: '1e5 * (t + 1)'}}}"))
    _refused(tmp_path, ["validate", str(tmp_path / "scene.yaml")], "scene.yaml:3:", "lights[0].motion.scalars.radiance: expression '1e5 * (t + 1)' is 100000 at frame 0",
             "half-float frame", capsys=capsys)
    (tmp_path / "scene.yaml").write_text(BASE.replace(light, "{type: constant, radiance: 0.5, motion: {type: keyframes, interpolation: catmull-rom, channels: {radiance: "
                                        "{keys: [{time: 0, value: 0}, {time: 1, value: 65000}, {time: 2, value: 65000}]}}}}"))
    # every key holds in a half; the spline overshoots them between frames 1 and 2 (at a shutter sample)
    _refused(tmp_path, _render(tmp_path), "scene.yaml:3:", "lights[0].motion: light 'light0': radiance reaches 6", "beyond what a half-float EXR holds", capsys=capsys)
    (tmp_path / "scene.yaml").write_text(BASE.replace(light, "{type: constant, radiance: 0.5, motion: {type: procedural, scalars: {radiance: '10**24 * 10**24'}}}"))
    _refused(tmp_path, ["validate", str(tmp_path / "scene.yaml")], "scene.yaml:3:", "is 1e+48 at frame 0 (t = 0 s): beyond what the renderer's float32 holds", capsys=capsys)
    (tmp_path / "scene.yaml").write_text(BASE.replace("radius: 0.5}", "radius: 0.5, transform: {translate: [1.0e39, 0, 0]}, radious: 1}"))
    with pytest.raises(SceneError) as err:
        load_scene(tmp_path / "scene.yaml")
    assert [p.yaml_path for p in err.value.problems] == ["objects[0].transform.translate[0]", "objects[0].radious"]
    (tmp_path / "scene.yaml").write_text(BASE)
    for key, why in (("samples/objects/ball/translation", "object 'ball': translation is not finite in the renderer's float32"),
                     ("at_frame/light_scalars/light0/radiance", "light 'light0': radiance is not finite in the renderer's float32")):
        path = _bake_npz(tmp_path, lambda a: a[key].__setitem__((1, ...), 1e39))
        _refused(tmp_path, _render(tmp_path, "--motion", str(path)), "m.npz", "frame 1:", why, capsys=capsys)
    # a bake file's environment radiance past a half (the frames are half-float)
    path = _bake_npz(tmp_path, lambda a: a["samples/light_scalars/light0/radiance"].__setitem__((1, ...), 1e5))
    _refused(tmp_path, _render(tmp_path, "--motion", str(path)), "m.npz", "frame 1: light 'light0': radiance reaches 100000", "half-float", capsys=capsys)


def test_a_zero_length_ik_bone_is_refused_at_validation(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 24, degenerate but valid: a chain joint at its parent's origin that nothing
    moves was found only by the bake (`motion validate` said ok)."""
    from motion.cli.main import main as motion_main

    (tmp_path / "scene.yaml").write_text(BASE.replace("  - {name: ball, shape: sphere, radius: 0.5}\n", "  - {name: a, shape: sphere, radius: 0.1}\n  - {name: b, shape: sphere, radius: 0.1, parent: a}\n"
                                                      "  - {name: c, shape: sphere, radius: 0.1, parent: b, transform: {translate: [0, 1, 0]}}\n  - {name: t, shape: sphere, radius: 0.1, transform: {translate: [1, 0, 0]}}\n")
                                         + "ik: [{chain: [a, b, c], target: t}]\n")
    _refused(tmp_path, ["validate", str(tmp_path / "scene.yaml")], "scene.yaml:10:18:", "ik[0].chain[1]: the bone a -> b has no length", capsys=capsys)
    # a keyed translation gives the bone its length: valid (the bake refuses it where it is 0)
    (tmp_path / "scene.yaml").write_text((tmp_path / "scene.yaml").read_text().replace("parent: a}", "parent: a, motion: {type: keyframes, channels: {translate: {keys: [{time: 0, value: [0, 1, 0]}]}}}}"))
    assert motion_main(["validate", str(tmp_path / "scene.yaml")]) == 0
