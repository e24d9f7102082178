"""Generate the example character scenes/assets/walker.glb: a skinned, keyframed glTF 2.0
figure (hips, spine, head, two legs and two arms as joints; one textured body mesh skinned
to them) with a looping two-second walk cycle: the hips travel forward and bob (LINEAR),
the legs and arms swing (CUBICSPLINE with explicit tangents), the head turns (LINEAR slerp).

    python tools/make_walker.py [OUT.glb]      # default scenes/assets/walker.glb

Written with tools/gltf_writer.py (json + numpy). Deterministic: the same bytes every run.
"""

from __future__ import annotations

import io
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from gltf_writer import GltfBuilder  # noqa: E402

CYCLE = 2.0  # seconds per walk cycle (two steps)
STRIDE = 1.4  # metres travelled per cycle


def quat_x(deg: float) -> list[float]:
    """glTF quaternion (x, y, z, w) of a rotation about +X."""
    h = math.radians(deg) / 2
    return [math.sin(h), 0.0, 0.0, math.cos(h)]


def quat_y(deg: float) -> list[float]:
    h = math.radians(deg) / 2
    return [0.0, math.sin(h), 0.0, math.cos(h)]


def box(center: tuple[float, float, float], size: tuple[float, float, float], rings: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A box subdivided along Y into `rings` (so it bends smoothly): positions, normals,
    uvs, triangles (flat faces, 4 vertices per quad)."""
    cx, cy, cz = center
    sx, sy, sz = (s / 2 for s in size)
    ys = np.linspace(cy - sy, cy + sy, rings + 1)
    pos, nrm, uv, tri = [], [], [], []
    sides = [((1, 0, 0), (0, 0, -1)), ((-1, 0, 0), (0, 0, 1)), ((0, 0, 1), (1, 0, 0)), ((0, 0, -1), (-1, 0, 0))]
    for s, (n, tangent) in enumerate(sides):
        n, tangent = np.array(n, float), np.array(tangent, float)
        for r in range(rings):
            base = len(pos)
            for y, du in ((ys[r], 0), (ys[r + 1], 1)):
                for side in (-1, 1):
                    p = np.array([cx, y, cz]) + n * np.array([sx, 0, sz]) + side * tangent * np.array([sx, 0, sz])
                    pos.append(p)
                    nrm.append(n)
                    uv.append(((s + (side + 1) / 2) / 4, 1 - (r + du) / rings))
            tri += [(base, base + 1, base + 3), (base, base + 3, base + 2)]
    for n, y in (((0, 1, 0), cy + sy), ((0, -1, 0), cy - sy)):
        base = len(pos)
        for dx, dz in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            pos.append((cx + dx * sx, y, cz + dz * sz))
            nrm.append(n)
            uv.append(((dx + 1) / 4, (dz + 1) / 4))
        quad = [(base, base + 2, base + 1), (base, base + 3, base + 2)] if n[1] < 0 else [(base, base + 1, base + 2), (base, base + 2, base + 3)]
        tri += quad
    return np.array(pos, float), np.array(nrm, float), np.array(uv, float), np.array(tri, np.int64)


def checker_png(size: int = 64) -> bytes:
    from PIL import Image

    yy, xx = np.mgrid[0:size, 0:size]
    tile = ((xx // 8 + yy // 8) % 2).astype(bool)
    img = np.where(tile[..., None], [230, 200, 60], [40, 90, 200]).astype(np.uint8)
    out = io.BytesIO()
    Image.fromarray(img).save(out, format="PNG", optimize=False)
    return out.getvalue()


def build(path: Path) -> Path:
    b = GltfBuilder()
    g = b.gltf
    # joints: rest pose (metres, Y up, facing +Z)
    hips = b.node(name="Hips", translation=[0.0, 0.95, 0.0], children=[])
    spine = b.node(name="Spine", translation=[0.0, 0.1, 0.0], children=[])
    head = b.node(name="Head", translation=[0.0, 0.6, 0.0])
    legs = [b.node(name=f"{s}Leg", translation=[x, -0.05, 0.0]) for s, x in (("Left", 0.13), ("Right", -0.13))]
    arms = [b.node(name=f"{s}Arm", translation=[x, 0.55, 0.0]) for s, x in (("Left", 0.3), ("Right", -0.3))]
    g["nodes"][hips]["children"] = [spine, *legs]
    g["nodes"][spine]["children"] = [head, *arms]
    joints = [hips, spine, head, *legs, *arms]
    # world bind positions of the joints (no rotation in the rest pose)
    bind = {hips: (0, 0.95, 0), spine: (0, 1.05, 0), head: (0, 1.65, 0), legs[0]: (0.13, 0.9, 0), legs[1]: (-0.13, 0.9, 0), arms[0]: (0.3, 1.6, 0), arms[1]: (-0.3, 1.6, 0)}
    parts = [  # (centre, size, rings, joint, blend-to joint near the top)
        ((0, 1.3, 0), (0.42, 0.5, 0.24), 4, spine, hips),
        ((0, 1.0, 0), (0.4, 0.14, 0.22), 1, hips, None),
        ((0, 1.8, 0), (0.24, 0.26, 0.24), 2, head, None),
        ((0.13, 0.48, 0), (0.14, 0.86, 0.16), 8, legs[0], hips),
        ((-0.13, 0.48, 0), (0.14, 0.86, 0.16), 8, legs[1], hips),
        ((0.3, 1.28, 0), (0.1, 0.62, 0.12), 6, arms[0], spine),
        ((-0.3, 1.28, 0), (0.1, 0.62, 0.12), 6, arms[1], spine),
    ]
    P, N, U, T, J, W = [], [], [], [], [], []
    for centre, size, rings, joint, blend in parts:
        p, n, uv, tri = box(centre, size, rings)
        T.append(tri + sum(len(x) for x in P))
        P.append(p)
        N.append(n)
        U.append(uv)
        top = centre[1] + size[1] / 2
        # weight fades to the parent joint over the top 15 cm (a soft bend at the joint)
        fade = np.clip((top - p[:, 1]) / 0.15, 0, 1) if blend is not None else np.ones(len(p))
        j = np.zeros((len(p), 4), np.uint16)
        w = np.zeros((len(p), 4), np.float32)
        j[:, 0] = joints.index(joint)
        j[:, 1] = joints.index(blend) if blend is not None else 0
        w[:, 0] = fade
        w[:, 1] = 1 - fade
        J.append(j)
        W.append(w)
    pos, nrm, uv, tri = (np.concatenate(x) for x in (P, N, U, T))
    attrs = {
        "POSITION": b.accessor(pos, target="vertex", bounds=True),
        "NORMAL": b.accessor(nrm, target="vertex"),
        "TEXCOORD_0": b.accessor(uv, target="vertex"),
        "JOINTS_0": b.accessor(np.concatenate(J), dtype="uint16", target="vertex"),
        "WEIGHTS_0": b.accessor(np.concatenate(W), target="vertex"),
    }
    tex = b.image(checker_png())
    g["materials"] = [{"name": "Cloth", "pbrMetallicRoughness": {"baseColorTexture": {"index": tex}, "metallicFactor": 0.0, "roughnessFactor": 0.7}}]
    g["meshes"].append({"name": "Body", "primitives": [{"attributes": attrs, "indices": b.accessor(tri.ravel(), dtype="uint32", target="index"), "material": 0}]})
    ibm = np.stack([np.linalg.inv(np.array([[1, 0, 0, bind[k][0]], [0, 1, 0, bind[k][1]], [0, 0, 1, bind[k][2]], [0, 0, 0, 1]], float)) for k in joints])
    g["skins"] = [{"name": "Rig", "joints": joints, "inverseBindMatrices": b.accessor(ibm), "skeleton": hips}]
    body = b.node(name="Body", mesh=0, skin=0)
    g["scenes"][0]["nodes"] = [hips, body]

    # the walk: hips travel and bob (LINEAR), limbs swing (CUBICSPLINE), head turns (LINEAR)
    times = np.linspace(0.0, CYCLE, 9)
    phase = 2 * np.pi * times / CYCLE
    hips_t = np.column_stack((0.03 * np.sin(phase), 0.95 + 0.03 * np.cos(2 * phase), STRIDE * times / CYCLE))
    samplers, channels = [], []

    def add(node: int, path: str, t: np.ndarray, values: np.ndarray, interp: str) -> None:
        samplers.append({"input": b.accessor(t, bounds=True), "output": b.accessor(values), "interpolation": interp})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": node, "path": path}})

    add(hips, "translation", times, hips_t, "LINEAR")
    add(head, "rotation", times, np.array([quat_y(15 * math.sin(p)) for p in phase]), "LINEAR")
    # CUBICSPLINE swing: value and its time derivative (tangent, per second) at each key
    for k, (node, amp, sign) in enumerate(((legs[0], 30, 1), (legs[1], 30, -1), (arms[0], 25, -1), (arms[1], 25, 1))):
        vals = []
        for p in phase:
            angle = sign * amp * math.sin(p)
            rate = sign * amp * math.cos(p) * 2 * math.pi / CYCLE  # degrees per second
            q = np.array(quat_x(angle))
            # dq/dt of a rotation about X: d/dt (sin(a/2), 0, 0, cos(a/2)) = (cos, 0, 0, -sin) a'/2
            h = math.radians(angle) / 2
            dq = np.array([math.cos(h), 0.0, 0.0, -math.sin(h)]) * math.radians(rate) / 2
            vals += [dq, q, dq]
        add(node, "rotation", times, np.array(vals), "CUBICSPLINE")
    g["animations"] = [{"name": "Walk", "samplers": samplers, "channels": channels}]
    path.parent.mkdir(parents=True, exist_ok=True)
    return b.save(path)


if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[1] / "scenes" / "assets" / "walker.glb"
    print(build(out))
