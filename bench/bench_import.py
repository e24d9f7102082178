"""Benchmark: glTF import and first-frame cost, cold vs warm asset cache, and per-frame
evaluation of skinned meshes (docs/imports.md).

    python bench/bench_import.py [--nodes 100] [--tris 10000] [--skinned 100] [--verts 10000]

1. A glTF of `nodes` animated nodes, each with a mesh of `tris` triangles (1M in all by
   default): `load_scene` (parse, convert meshes to PLY in the import cache) plus the
   renderer's mesh conversion (render/assets.mesh_file) plus the motion at frame 0,
   first with an empty cache (cold), then again with the cache filled (warm).
2. A glTF of `skinned` meshes of `verts` vertices on a 3-joint rig: seconds to evaluate
   one frame's motion (9 shutter samples, as `render.shutter_samples` defaults).
The cache lives in a temporary MOTION_CACHE_DIR, so your own cache is untouched.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_model  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))


def grid(n_tris: int) -> tuple[np.ndarray, np.ndarray]:
    """A square grid with about n_tris triangles: vertices, triangle indices."""
    side = max(1, int(round((n_tris / 2) ** 0.5)))
    u, v = np.meshgrid(np.linspace(0, 1, side + 1), np.linspace(0, 1, side + 1))
    verts = np.column_stack((u.ravel(), v.ravel(), np.zeros(u.size)))
    i, j = np.meshgrid(np.arange(side), np.arange(side))
    a = (j * (side + 1) + i).ravel()
    tris = np.concatenate((np.stack((a, a + 1, a + side + 2), 1), np.stack((a, a + side + 2, a + side + 1), 1)))
    return verts, tris


def write_static(path: Path, nodes: int, tris: int) -> None:
    from gltf_writer import GltfBuilder

    b = GltfBuilder()
    times = np.linspace(0, 2, 25)
    samplers, channels = [], []
    for k in range(nodes):
        verts, faces = grid(tris)
        pos = b.accessor(verts + [k % 10, k // 10, 0], target="vertex", bounds=True)
        b.gltf["meshes"].append({"primitives": [{"attributes": {"POSITION": pos}, "indices": b.accessor(faces.ravel(), dtype="uint32", target="index")}]})
        node = b.node(name=f"N{k}", mesh=k)
        b.gltf["scenes"][0]["nodes"].append(node)
        samplers.append({"input": b.accessor(times, bounds=True), "output": b.accessor(np.column_stack((np.sin(times + k), times, np.zeros_like(times)))), "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": node, "path": "translation"}})
    b.gltf["animations"] = [{"samplers": samplers, "channels": channels}]
    b.save(path)


def write_skinned(path: Path, meshes: int, verts: int) -> None:
    from gltf_writer import GltfBuilder

    b = GltfBuilder()
    g = b.gltf
    root = b.node(name="Root", children=[1])
    b.node(name="Mid", translation=[0, 1, 0], children=[2])
    b.node(name="Tip", translation=[0, 1, 0])
    ibm = np.stack([np.eye(4)] * 3)
    ibm[1, 1, 3], ibm[2, 1, 3] = -1, -2
    g["skins"] = [{"joints": [0, 1, 2], "inverseBindMatrices": b.accessor(ibm)}]
    g["scenes"][0]["nodes"] = [root]
    for k in range(meshes):
        v, faces = grid(2 * verts)
        v = v[:verts] * [1, 2, 1]
        faces = faces[(faces < verts).all(axis=1)]
        w = np.column_stack((np.clip(1 - v[:, 1], 0, 1), 1 - np.abs(v[:, 1] - 1), np.clip(v[:, 1] - 1, 0, 1), np.zeros(len(v)))) + [0.01, 0.01, 0.01, 0]
        w /= w.sum(1, keepdims=True)
        j = np.tile(np.array([0, 1, 2, 0], np.uint16), (len(v), 1))
        attrs = {"POSITION": b.accessor(v, target="vertex", bounds=True), "JOINTS_0": b.accessor(j, dtype="uint16", target="vertex"), "WEIGHTS_0": b.accessor(w, target="vertex")}
        g["meshes"].append({"primitives": [{"attributes": attrs, "indices": b.accessor(faces.ravel(), dtype="uint32", target="index")}]})
        g["scenes"][0]["nodes"].append(b.node(name=f"S{k}", mesh=k, skin=0))
    times = np.linspace(0, 2, 9)
    half = np.radians(30 * np.sin(np.pi * times)) / 2
    rot = np.column_stack((np.sin(half), 0 * half, 0 * half, np.cos(half)))
    g["animations"] = [{"samplers": [{"input": b.accessor(times, bounds=True), "output": b.accessor(rot)}], "channels": [{"sampler": 0, "target": {"node": 1, "path": "rotation"}}, {"sampler": 0, "target": {"node": 2, "path": "rotation"}}]}]
    b.save(path)


def scene(folder: Path, asset: str) -> Path:
    path = folder / f"{Path(asset).stem}.yaml"
    path.write_text(f"camera: {{position: [5, 5, 20], look_at: [5, 5, 0]}}\ntimeline: {{fps: 24, last: 47}}\nimports: [{{file: {asset}}}]\n")
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, default=100)
    ap.add_argument("--tris", type=int, default=10_000)
    ap.add_argument("--skinned", type=int, default=100)
    ap.add_argument("--verts", type=int, default=10_000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        os.environ["MOTION_CACHE_DIR"] = str(tmp / "cache")
        from motion.pipeline.motion.evaluate import evaluate
        from motion.pipeline.render.translate.assets import mesh_file
        from motion.pipeline.scene.loader import load_scene
        from motion.pipeline.variant import activate

        activate("auto", quiet=True)
        write_static(tmp / "crowd.glb", args.nodes, args.tris)
        size = (tmp / "crowd.glb").stat().st_size
        shot = scene(tmp, "crowd.glb")
        results = {}
        for label in ("cold", "warm"):
            t0 = time.perf_counter()
            loaded = load_scene(shot)
            t1 = time.perf_counter()
            for obj in loaded.scene.objects:
                if obj.shape == "mesh":
                    mesh_file(loaded.asset(obj.file))
            t2 = time.perf_counter()
            evaluate(loaded, np.array([0.0]))
            t3 = time.perf_counter()
            results[label] = (t1 - t0, t2 - t1, t3 - t2)
        print(f"CPU: {cpu_model()} (shared machine: figures are noisy)")
        print(f"1) {args.nodes} animated nodes x {args.tris} triangles ({size / 1e6:.1f} MB .glb):")
        for label, (imp, conv, ev) in results.items():
            print(f"   {label}: import {imp:7.3f} s + renderer mesh cache {conv:7.3f} s + motion at frame 0 {ev:6.3f} s = {imp + conv + ev:7.3f} s")
        cold, warm = (sum(results[k]) for k in ("cold", "warm"))
        print(f"   warm / cold = {warm / cold:.3f}")

        write_skinned(tmp / "skinned.glb", args.skinned, args.verts)
        loaded = load_scene(scene(tmp, "skinned.glb"))
        shutter = np.linspace(0.5, 0.5 + 1 / 48, 9)
        evaluate(loaded, shutter)  # first call reads the bind meshes and skin files
        n = 5
        t0 = time.perf_counter()
        for f in range(n):
            motion = evaluate(loaded, shutter + f / 24)
        per = (time.perf_counter() - t0) / n
        count = sum(v.shape[1] for v in motion.vertices.values())
        print(f"2) {args.skinned} skinned meshes x {args.verts} vertices ({count} in all), 9 shutter samples per frame:")
        print(f"   evaluation {per:.3f} s per frame ({per / 9 * 1e3:.1f} ms per sample time)")


if __name__ == "__main__":
    main()
