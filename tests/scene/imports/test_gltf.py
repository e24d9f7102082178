"""glTF imports: round trips against an independent evaluator (the glTF specification's
formulas, written here), located errors for bad files, the Khronos validator on the
assets we write, and a render of an imported skinned character.

Assets are written with tools/gltf_writer.py (json + numpy), not with pygltflib, which
is what the importer reads with."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from _support import assert_card_upright, run_motion
from motion.pipeline.errors import SceneError
from motion.pipeline.motion.evaluate import evaluate
from motion.pipeline.scene.loader import load_scene

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "tools"))
from gltf_writer import GltfBuilder  # noqa: E402

FPS = 24
# frame times, sub-frame times, exact key times, and times before / after the keys
TIMES = np.array([-0.2, 0.0, 1 / FPS, 0.1, 0.25, 0.3 + 0.37 / FPS, 0.5, 0.61, 0.75, 0.99, 1.0, 1.2, 23.5 / FPS])


# --- the independent evaluator: the glTF 2.0 specification's formulas ---------------------


def quat_matrix(q):  # glTF order (x, y, z, w)
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def spec_slerp(a, b, u):
    d = float(np.dot(a, b))
    if d < 0:  # the specification's shortest path
        b, d = -b, -d
    angle = math.acos(min(d, 1.0))
    if angle < 1e-12:
        return a
    return (math.sin((1 - u) * angle) * a + math.sin(u * angle) * b) / math.sin(angle)


def sample(times, values, interp, t, rotation):
    """One sampler at time t (clamped outside the keys)."""
    n = len(times)
    if interp == "CUBICSPLINE":
        a, v, b = values[0::3], values[1::3], values[2::3]
    else:
        v = values
    if t <= times[0]:
        out = v[0]
    elif t >= times[-1]:
        out = v[-1]
    else:
        k = int(np.searchsorted(times, t, side="right") - 1)
        td = times[k + 1] - times[k]
        u = (t - times[k]) / td
        if interp == "STEP":
            out = v[k]
        elif interp == "LINEAR":
            out = spec_slerp(v[k], v[k + 1], u) if rotation else (1 - u) * v[k] + u * v[k + 1]
        else:
            u2, u3 = u * u, u * u * u
            out = (2 * u3 - 3 * u2 + 1) * v[k] + td * (u3 - 2 * u2 + u) * b[k] + (-2 * u3 + 3 * u2) * v[k + 1] + td * (u3 - u2) * a[k + 1]
    assert n == len(v)
    return out / np.linalg.norm(out) if rotation else out


class SpecWorld:
    """World matrices of a glTF node tree and skinned / morphed vertices at time t."""

    def __init__(self, gltf, arrays, root=np.eye(4)):
        self.g, self.arrays, self.root = gltf, arrays, root
        self.parent = {c: p for p, n in enumerate(gltf["nodes"]) for c in n.get("children", [])}

    def local(self, k, t):
        n = self.g["nodes"][k]
        if "matrix" in n:
            return np.asarray(n["matrix"], float).reshape(4, 4).T
        trs = {"translation": np.asarray(n.get("translation", [0, 0, 0]), float), "rotation": np.asarray(n.get("rotation", [0, 0, 0, 1]), float), "scale": np.asarray(n.get("scale", [1, 1, 1]), float)}
        for anim in self.g.get("animations", [])[:1]:
            for ch in anim["channels"]:
                if ch["target"]["node"] == k and ch["target"]["path"] in trs:
                    s = anim["samplers"][ch["sampler"]]
                    trs[ch["target"]["path"]] = sample(self.arrays[s["input"]][:, 0], self.arrays[s["output"]], s.get("interpolation", "LINEAR"), t, ch["target"]["path"] == "rotation")
        m = np.eye(4)
        m[:3, :3] = quat_matrix(trs["rotation"]) * trs["scale"][None, :]
        m[:3, 3] = trs["translation"]
        return m

    def world(self, k, t):
        m = self.local(k, t)
        while k in self.parent:
            k = self.parent[k]
            m = self.local(k, t) @ m
        return self.root @ m

    def weights(self, k, t):
        n = self.g["nodes"][k]
        w = np.asarray(n.get("weights", self.g["meshes"][n["mesh"]].get("weights")), float)
        for ch in self.g["animations"][0]["channels"]:
            if ch["target"]["node"] == k and ch["target"]["path"] == "weights":
                s = self.g["animations"][0]["samplers"][ch["sampler"]]
                vals = self.arrays[s["output"]][:, 0].reshape(-1, len(w))
                w = sample(self.arrays[s["input"]][:, 0], vals, s.get("interpolation", "LINEAR"), t, False)
        return w

    def vertices(self, k, t):
        """World-space vertices of node k's first primitive (morphed, then skinned)."""
        n = self.g["nodes"][k]
        prim = self.g["meshes"][n["mesh"]]["primitives"][0]
        v = self.arrays[prim["attributes"]["POSITION"]].copy()
        for w, target in zip(self.weights(k, t) if prim.get("targets") else [], prim.get("targets", [])):
            v = v + w * self.arrays[target["POSITION"]]
        if "skin" not in n:
            return (self.world(k, t) @ np.c_[v, np.ones(len(v))].T).T[:, :3]
        skin = self.g["skins"][n["skin"]]
        ibm = self.arrays[skin["inverseBindMatrices"]].reshape(-1, 4, 4).transpose(0, 2, 1)
        mats = np.stack([self.world(j, t) @ ibm[i] for i, j in enumerate(skin["joints"])])
        joints, weights = self.arrays[prim["attributes"]["JOINTS_0"]], self.arrays[prim["attributes"]["WEIGHTS_0"]]
        blended = np.einsum("vk,vkij->vij", weights, mats[joints.astype(int)])
        return np.einsum("vij,vj->vi", blended, np.c_[v, np.ones(len(v))])[:, :3]


# --- a test asset ---------------------------------------------------------------------------


def qx(deg):
    h = math.radians(deg) / 2
    return [math.sin(h), 0.0, 0.0, math.cos(h)]


def qaxis(axis, deg):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    h = math.radians(deg) / 2
    return [*(a * math.sin(h)), math.cos(h)]


def build_asset(path: Path, png: bytes | None = None) -> tuple[dict, dict]:
    """Root > Arm > Hand > Prop (matrix node with a mesh), a skinned Strip on the three
    joints, a morphing Face, a camera and a spot light; every interpolation mode."""
    b = GltfBuilder()
    g = b.gltf
    arrays: dict[int, np.ndarray] = {}

    def acc(a, **kw):
        i = b.accessor(a, **kw)
        arr = np.asarray(a, np.float32).astype(np.float64) if kw.get("dtype", "float32") == "float32" else np.asarray(a)
        if arr.ndim == 3:
            arr = arr.transpose(0, 2, 1).reshape(len(arr), 16)
        arrays[i] = arr if arr.ndim == 2 else arr[:, None]
        return i

    root = b.node(name="Root", translation=[0.5, 0.0, -1.0], rotation=qaxis([0, 1, 0], 20), scale=[1.5, 1.5, 1.5], children=[])
    arm = b.node(name="Arm", translation=[0.0, 1.0, 0.0], children=[])
    hand = b.node(name="Hand", translation=[0.0, 0.8, 0.0], children=[])
    prop = b.node(name="Prop", matrix=[0.5, 0, 0, 0, 0, 0.25, 0, 0, 0, 0, 1, 0, 0.1, 0.2, 0.3, 1], mesh=0)
    g["nodes"][root]["children"] = [arm]
    g["nodes"][arm]["children"] = [hand]
    g["nodes"][hand]["children"] = [prop]
    # a little quad for the prop
    quad = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    g["meshes"].append({"name": "Card", "primitives": [{"attributes": {"POSITION": acc(quad, target="vertex", bounds=True), "TEXCOORD_0": acc(np.array([[0, 1], [1, 1], [1, 0], [0, 0]], float), target="vertex")}, "indices": acc(np.array([0, 1, 2, 0, 2, 3]), dtype="uint16", target="index"), "material": 0}]})
    mat: dict = {"name": "Paint", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.2, 0.1, 1.0], "metallicFactor": 0.25, "roughnessFactor": 0.6}, "doubleSided": True}
    if png is not None:
        mat["pbrMetallicRoughness"]["baseColorTexture"] = {"index": b.image(png)}
    g["materials"] = [mat]
    # a strip of 3 x 6 vertices along +Y skinned to Root, Arm, Hand
    ys = np.linspace(0, 2, 6)
    strip = np.array([[x, y, 0.0] for y in ys for x in (-0.2, 0.0, 0.2)])
    tris = [(r * 3 + c, r * 3 + c + 1, r * 3 + c + 4) for r in range(5) for c in range(2)] + [(r * 3 + c, r * 3 + c + 4, r * 3 + c + 3) for r in range(5) for c in range(2)]
    joints = np.zeros((len(strip), 4), np.uint16)
    weights = np.zeros((len(strip), 4), np.float32)
    for v, (_, y, _) in enumerate(strip):
        joints[v, :3] = (0, 1, 2)
        w = np.array([max(0, 1 - y), 1 - abs(y - 1), max(0, y - 1)]) + 0.1
        weights[v, :3] = w / w.sum()
    weights[:, :3] /= weights[:, :3].astype(np.float64).sum(axis=1, keepdims=True).astype(np.float32)
    g["meshes"].append({"name": "Strip", "primitives": [{"attributes": {"POSITION": acc(strip, target="vertex", bounds=True), "JOINTS_0": acc(joints, dtype="uint16", target="vertex"), "WEIGHTS_0": acc(weights, target="vertex")}, "indices": acc(np.array(tris).ravel(), dtype="uint16", target="index")}]})
    bind_world = {root: np.eye(4), arm: np.eye(4), hand: np.eye(4)}
    bind_world[arm][1, 3] = 1.0
    bind_world[hand][1, 3] = 1.8
    bind_world[root] = np.diag([1.0, 1.0, 1.0, 1.0])
    ibm = np.stack([np.linalg.inv(bind_world[j]) for j in (root, arm, hand)])
    g["skins"] = [{"joints": [root, arm, hand], "inverseBindMatrices": acc(ibm)}]
    strip_node = b.node(name="Strip", mesh=1, skin=0)
    # a morphing face: a triangle with two targets
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    t0 = np.array([[0, 0, 0.5], [0, 0, 0], [0, 0, 0]], float)
    t1 = np.array([[0, 0, 0], [0.3, 0.3, 0], [0, 0, -0.2]], float)
    g["meshes"].append({"name": "Face", "weights": [0.25, 0.0], "extras": {"targetNames": ["Smile", "Blink"]}, "primitives": [{"attributes": {"POSITION": acc(tri, target="vertex", bounds=True)}, "targets": [{"POSITION": acc(t0, target="vertex", bounds=True)}, {"POSITION": acc(t1, target="vertex", bounds=True)}]}]})
    face = b.node(name="Face", mesh=2, translation=[2.0, 0.0, 0.0])
    cam = b.node(name="Cam", camera=0, translation=[0, 1, 5], rotation=qaxis([1, 0, 0], -10))
    g["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.7, "znear": 0.05, "zfar": 100.0, "aspectRatio": 1.5}}]
    lamp = b.node(name="Lamp", translation=[0, 3, 0], rotation=qx(-90), extensions={"KHR_lights_punctual": {"light": 0}})
    g["extensionsUsed"] = ["KHR_lights_punctual"]
    g["extensions"] = {"KHR_lights_punctual": {"lights": [{"type": "spot", "color": [1.0, 0.9, 0.8], "intensity": 20.0, "spot": {"innerConeAngle": 0.3, "outerConeAngle": 0.6}}]}}
    g["scenes"][0]["nodes"] = [root, strip_node, face, cam, lamp]

    samplers, channels = [], []

    def add(node, path, times, values, interp):
        samplers.append({"input": acc(np.asarray(times, float), bounds=True), "output": acc(np.asarray(values, float)), "interpolation": interp})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": node, "path": path}})

    # Arm: LINEAR translation; LINEAR rotation with a sign-flipped key (slerp takes the short way)
    add(arm, "translation", [0.0, 0.5, 1.0], [[0, 1, 0], [0.3, 1.2, -0.1], [0, 0.9, 0.4]], "LINEAR")
    q2 = -np.asarray(qaxis([1, 1, 0], 100))
    add(arm, "rotation", [0.0, 0.4, 1.0], [qaxis([0, 0, 1], 10), qaxis([1, 0, 1], 60), q2], "LINEAR")
    add(arm, "scale", [0.0, 0.3, 0.7], [[1, 1, 1], [1.2, 1.2, 1.2], [0.9, 0.9, 0.9]], "STEP")
    # Hand: CUBICSPLINE rotation and translation with the file's tangents (a, v, b per key)
    rot = []
    for q, da, db in ((qx(0), [0.2, 0, 0.1, 0], [0.5, 0.1, 0, 0]), (qaxis([1, 0.5, 0], 70), [0.3, -0.2, 0, -0.1], [0.1, 0.4, 0, 0.2]), (qaxis([0, 1, 0.3], 40), [0, 0, 0, 0], [0, 0, 0, 0])):
        rot += [da, q, db]
    add(hand, "rotation", [0.0, 0.45, 1.0], rot, "CUBICSPLINE")
    add(hand, "translation", [0.0, 0.6, 1.0], [[0, 0, 0], [0, 0.8, 0], [1, 0, 0], [0.5, 0.5, 0], [0.1, 0.7, 0.2], [0, -1, 0], [0, 0, 0], [0, 0.8, 0], [0, 0, 0]], "CUBICSPLINE")
    # Face: morph weights, CUBICSPLINE (in, value, out per key, 2 targets each)
    add(face, "weights", [0.0, 0.5, 1.0], [0, 0, 0.1, 0.0, 1, -1, 0.5, 0, 1.0, 0.5, 0, 0, 0, 0, 0.2, 0.8, 0, 0], "CUBICSPLINE")
    g["animations"] = [{"name": "Take", "samplers": samplers, "channels": channels}]
    b.save(path)
    return g, arrays


def scene_yaml(tmp: Path, asset: str, extra: str = "", imports_extra: str = "") -> Path:
    path = tmp / "shot.yaml"
    path.write_text(
        f"""name: imported
timeline: {{fps: {FPS}, first: 0, last: 24}}
imports:
  - file: {asset}
    prefix: "a."
    transform: {{translate: [1, 2, 3], rotate: {{axis: [0, 1, 0], angle: 30}}, scale: 2}}
{imports_extra}
lights:
  - {{type: constant, radiance: 0.3}}
render: {{resolution: [32, 24], spp: 2}}
{extra}
"""
    )
    return path


def root_matrix() -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = quat_matrix(np.array(qaxis([0, 1, 0], 30))) * 2.0
    m[:3, 3] = (1, 2, 3)
    return m


@pytest.fixture(autouse=True, scope="module")
def fresh_cache(tmp_path_factory):
    """A cache of our own: every run converts cold first (and leaves the user's alone)."""
    mp = pytest.MonkeyPatch()
    mp.setenv("MOTION_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
    yield
    mp.undo()


@pytest.fixture(scope="module")
def asset(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("gltf")
    g, arrays = build_asset(tmp / "rig.glb")
    return tmp, g, arrays


def test_world_matrices_match_the_specification_at_frames_and_subframes(asset):
    tmp, g, arrays = asset
    loaded = load_scene(scene_yaml(tmp, "rig.glb"))
    motion = evaluate(loaded, TIMES)
    spec = SpecWorld(g, arrays, root_matrix())
    for k, name in enumerate(["Root", "Arm", "Hand", "Prop"]):
        ours = motion.objects[f"a.{name}"].matrices()
        for i, t in enumerate(TIMES):
            np.testing.assert_allclose(ours[i], spec.world(k, t), atol=1e-5, err_msg=f"{name} at t={t}")


def test_units_and_up_axis_override_puts_a_stage_frame_under_the_root(asset, tmp_path):
    """glTF is metres and +Y up (nothing added); `units: 0.01, up_axis: z` on the entry
    puts a frame under the import's root that scales by 0.01 and turns +Z up to +Y up."""
    tmp, g, arrays = asset
    (tmp_path / "rig.glb").write_bytes((tmp / "rig.glb").read_bytes())
    loaded = load_scene(scene_yaml(tmp_path, "rig.glb", imports_extra="    units: 0.01\n    up_axis: z"))
    motion = evaluate(loaded, TIMES)
    turn = np.eye(4)
    turn[1:3, 1:3] = [[0, 1], [-1, 0]]  # -90 degrees about X: +Z -> +Y
    spec = SpecWorld(g, arrays, root_matrix() @ turn @ np.diag([0.01, 0.01, 0.01, 1.0]))
    for k, name in enumerate(["Root", "Arm", "Hand", "Prop"]):
        ours = motion.objects[f"a.{name}"].matrices()
        for i, t in enumerate(TIMES):
            np.testing.assert_allclose(ours[i], spec.world(k, t), atol=1e-5, err_msg=f"{name} at t={t}")
    assert "a.rig.stage" in [o.name for o in loaded.scene.objects]
    assert "a.rig.stage" not in [o.name for o in load_scene(scene_yaml(tmp_path, "rig.glb")).scene.objects]


def test_skinned_and_morphed_vertices_match_the_specification(asset):
    tmp, g, arrays = asset
    loaded = load_scene(scene_yaml(tmp, "rig.glb"))
    motion = evaluate(loaded, TIMES)
    spec = SpecWorld(g, arrays, root_matrix())
    nodes = {n["name"]: k for k, n in enumerate(g["nodes"])}
    for name, obj in (("Strip", "a.Strip.mesh"), ("Face", "a.Face")):
        pose = motion.objects[obj].matrices()
        local = motion.vertices[obj]
        for i, t in enumerate(TIMES):
            ours = np.einsum("ij,vj->vi", pose[i], np.c_[local[i], np.ones(len(local[i]))])[:, :3]
            np.testing.assert_allclose(ours, spec.vertices(nodes[name], t), atol=1e-5, err_msg=f"{name} at t={t}")


def test_materials_camera_and_lights_are_our_records(asset, tmp_path):
    tmp, g, arrays = asset
    loaded = load_scene(scene_yaml(tmp, "rig.glb", imports_extra="    camera: Cam"))
    scene = loaded.scene
    mat = next(m for m in scene.materials if m.name == "a.Paint")
    assert mat.type == "principled" and mat.two_sided
    assert mat.color == pytest.approx((0.8, 0.2, 0.1), abs=1e-6) and mat.metallic == 0.25 and mat.roughness == pytest.approx(0.6)
    assert next(o for o in scene.objects if o.name == "a.Prop").material == "a.Paint"
    cam = scene.camera
    assert cam.fov == pytest.approx(math.degrees(0.7)) and cam.fov_axis == "y" and cam.near == pytest.approx(0.05)
    motion = evaluate(loaded, np.array([0.0]))
    spec = SpecWorld(g, arrays, root_matrix())
    nodes = {n["name"]: k for k, n in enumerate(g["nodes"])}
    flip = np.diag([-1.0, 1.0, -1.0, 1.0])  # glTF looks along -Z, Mitsuba along +Z
    np.testing.assert_allclose(motion.camera.matrices()[0], spec.world(nodes["Cam"], 0.0) @ flip, atol=1e-6)
    spot = next(light for light in scene.lights if light.name == "a.Lamp.light")
    assert spot.type == "spot" and spot.cutoff_angle == pytest.approx(math.degrees(0.6)) and spot.beam_width == pytest.approx(math.degrees(0.3))
    assert spot.intensity == pytest.approx((20.0, 18.0, 16.0))
    # the spot sits at the node's origin and shines along the node's -Z (its frame's +Z)
    lamp, node = motion.lights["a.Lamp.light"].matrices()[0], spec.world(nodes["Lamp"], 0.0)
    np.testing.assert_allclose(lamp[:3, 3], node[:3, 3], atol=1e-6)
    np.testing.assert_allclose(lamp[:3, 2] / np.linalg.norm(lamp[:3, 2]), -node[:3, 2] / np.linalg.norm(node[:3, 2]), atol=1e-6)


def test_texture_is_extracted_to_the_asset_cache(tmp_path):
    from PIL import Image
    import io

    buf = io.BytesIO()
    Image.fromarray(np.full((4, 4, 3), 200, np.uint8)).save(buf, format="PNG")
    build_asset(tmp_path / "tex.glb", png=buf.getvalue())
    loaded = load_scene(scene_yaml(tmp_path, "tex.glb"))
    mat = next(m for m in loaded.scene.materials if m.name == "a.Paint")
    # the base colour factor multiplies the texture: baked in, in linear units
    pixels = np.asarray(Image.open(mat.color.file))
    lin = (200 / 255 + 0.055) / 1.055
    expect = [255 * (1.055 * (lin**2.4 * f) ** (1 / 2.4) - 0.055) for f in (0.8, 0.2, 0.1)]
    np.testing.assert_allclose(pixels[0, 0], expect, atol=1.0)


def test_overrides_by_name_are_validated_in_the_scene_file(asset):
    tmp, g, arrays = asset
    extra = "materials:\n  - {name: red, type: diffuse, color: [1, 0, 0]}\n"
    over = "    overrides:\n      a.Prop: {material: red, motion: {type: procedural, generators: [{type: turntable, rate: 90}]}}\n      a.Face: {material: blue}\n"
    with pytest.raises(SceneError) as err:
        load_scene(scene_yaml(tmp, "rig.glb", extra=extra, imports_extra=over))
    lines = str(err.value).splitlines()
    assert len(lines) == 1 and "shot.yaml:" in lines[0] and "imports[0].overrides.a.Face.material" in lines[0] and "unknown material 'blue'" in lines[0], lines
    loaded = load_scene(scene_yaml(tmp, "rig.glb", extra=extra, imports_extra=over.replace("a.Face: {material: blue}", "a.Face: {visible: false}")))
    prop = next(o for o in loaded.scene.objects if o.name == "a.Prop")
    assert prop.material == "red" and prop.motion.type == "procedural"
    with pytest.raises(SceneError, match=r"imports\[0\]\.overrides\.a\.Prob: no imported object or light named 'a\.Prob'; did you mean 'a\.Prop'"):
        load_scene(scene_yaml(tmp, "rig.glb", imports_extra="    overrides: {a.Prob: {visible: false}}"))


# --- bad files -----------------------------------------------------------------------------


def _one_line_error(path: Path) -> str:
    with pytest.raises(SceneError) as err:
        load_scene(path)
    text = str(err.value)
    assert "\n" not in text, text
    return text


def test_truncated_glb(asset, tmp_path):
    tmp, _, _ = asset
    data = (tmp / "rig.glb").read_bytes()
    (tmp_path / "cut.glb").write_bytes(data[: len(data) // 2])
    msg = _one_line_error(scene_yaml(tmp_path, "cut.glb"))
    assert "cut.glb: <glb header>: truncated .glb" in msg


def test_accessor_out_of_range(asset, tmp_path):
    tmp, g, _ = asset
    data = (tmp / "rig.glb").read_bytes()
    bad = json.loads(data[20 : 20 + int.from_bytes(data[12:16], "little")])
    pos = bad["meshes"][1]["primitives"][0]["attributes"]["POSITION"]
    bad["accessors"][pos]["count"] = 5000
    b = GltfBuilder()
    b.gltf, b.blob = bad, bytearray(data[20 + int.from_bytes(data[12:16], "little") + 8 :])
    b.save(tmp_path / "range.glb")
    msg = _one_line_error(scene_yaml(tmp_path, "range.glb"))
    assert f"range.glb: accessors[{pos}] (meshes[1] 'Strip'.primitives[0].attributes.POSITION): out of range" in msg
    # an accessor without a buffer view is zeros: its count must not make us allocate at will
    del bad["accessors"][pos]["bufferView"]
    bad["accessors"][pos]["count"] = 10**9
    b.save(tmp_path / "range.glb")
    msg = _one_line_error(scene_yaml(tmp_path, "range.glb"))
    assert f"range.glb: accessors[{pos}] (meshes[1] 'Strip'.primitives[0].attributes.POSITION): count 1000000000 is out of range" in msg


def test_missing_texture_file(tmp_path):
    b = GltfBuilder()
    pos = b.accessor(np.eye(3), target="vertex", bounds=True)
    b.gltf["meshes"].append({"primitives": [{"attributes": {"POSITION": pos}, "material": 0}]})
    b.gltf["images"] = [{"uri": "textures/skin.png"}]
    b.gltf["textures"] = [{"source": 0}]
    b.gltf["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    b.gltf["scenes"][0]["nodes"] = [b.node(name="Thing", mesh=0)]
    b.save(tmp_path / "tex.gltf")
    msg = _one_line_error(scene_yaml(tmp_path, "tex.gltf", extra="camera: {position: [0, 0, 5], look_at: [0, 0, 0]}"))
    assert "tex.gltf: images[0] 'textures/skin.png': texture file not found" in msg


def test_unsupported_required_extension(tmp_path):
    b = GltfBuilder()
    b.gltf["extensionsUsed"] = b.gltf["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    b.gltf["scenes"][0]["nodes"] = [b.node(name="Empty")]
    b.save(tmp_path / "draco.gltf")
    msg = _one_line_error(scene_yaml(tmp_path, "draco.gltf", extra="camera: {position: [0, 0, 5], look_at: [0, 0, 0]}"))
    assert "draco.gltf: extensionsRequired: unsupported extension 'KHR_draco_mesh_compression' is marked required" in msg


def test_bad_file_on_the_command_line_is_one_line_exit_2(asset, tmp_path):
    tmp, _, _ = asset
    data = (tmp / "rig.glb").read_bytes()
    (tmp_path / "cut.glb").write_bytes(data[:100])
    shot = scene_yaml(tmp_path, "cut.glb")
    proc = run_motion("validate", str(shot))
    assert proc.returncode == 2, proc.stderr
    lines = [line for line in (proc.stdout + proc.stderr).splitlines() if line.strip()]
    assert len(lines) == 1 and "cut.glb: <glb header>: truncated .glb" in lines[0] and "Traceback" not in proc.stderr


# --- the Khronos validator, where it runs here ------------------------------------------------


def _validator() -> Path | None:
    for base in (os.environ.get("GLTF_VALIDATOR_NODE_MODULES"), ROOT / ".node" / "node_modules"):
        if base and (Path(base) / "gltf-validator" / "index.js").is_file() and shutil.which("node"):
            return Path(base)
    return None


@pytest.mark.skipif(_validator() is None, reason="gltf-validator (npm) not installed: npm install --prefix .node gltf-validator")
def test_khronos_validator_accepts_our_assets(asset, tmp_path):
    tmp, _, _ = asset
    from make_walker import build

    walker = build(tmp_path / "walker.glb")
    script = """
const v = require('gltf-validator'); const fs = require('fs');
(async () => { for (const f of process.argv.slice(1)) {
  const r = await v.validateBytes(new Uint8Array(fs.readFileSync(f)));
  console.log(JSON.stringify({file: f, errors: r.issues.numErrors, messages: r.issues.messages.filter(m => m.severity === 0)}));
} })();
"""
    out = subprocess.run(["node", "-e", script, str(tmp / "rig.glb"), str(walker)], capture_output=True, text=True, cwd=_validator(), env={**os.environ, "NODE_PATH": str(_validator())}, timeout=60)
    assert out.returncode == 0, out.stderr
    reports = [json.loads(line) for line in out.stdout.splitlines()]
    assert len(reports) == 2
    for r in reports:
        assert r["errors"] == 0, r


@pytest.mark.render
def test_textured_card_renders_the_right_way_up(tmp_path):
    """glTF's uv (0, 0) is the image's top-left: a card whose texture is red above and
    blue below renders red at the top, through the asset cache and Mitsuba's PLY loader."""
    from PIL import Image
    import io

    img = np.zeros((8, 8, 3), np.uint8)
    img[:4], img[4:] = (255, 0, 0), (0, 0, 255)
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    b = GltfBuilder()
    pos = b.accessor(np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float), target="vertex", bounds=True)
    uv = b.accessor(np.array([[0, 1], [1, 1], [1, 0], [0, 0]], float), target="vertex")
    tex = b.image(buf.getvalue())
    b.gltf["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": tex}, "metallicFactor": 0, "roughnessFactor": 1}}]
    b.gltf["meshes"].append({"primitives": [{"attributes": {"POSITION": pos, "TEXCOORD_0": uv}, "indices": b.accessor(np.array([0, 1, 2, 0, 2, 3]), dtype="uint16", target="index"), "material": 0}]})
    b.gltf["scenes"][0]["nodes"] = [b.node(name="Card", mesh=0)]
    b.save(tmp_path / "card.glb")
    assert_card_upright(tmp_path, "card.glb")


# --- Blender as the authoring side, where bpy installs -------------------------------------


def _bpy_python() -> str | None:
    """A Python with bpy: $MOTION_BPY_PYTHON, else this one if it imports bpy."""
    env = os.environ.get("MOTION_BPY_PYTHON")
    if env and Path(env).is_file():
        return env
    probe = subprocess.run([sys.executable, "-c", "import bpy"], capture_output=True)
    return sys.executable if probe.returncode == 0 else None


@pytest.mark.slow
@pytest.mark.skipif(_bpy_python() is None, reason="bpy (Blender as a Python module) is not installed here; set MOTION_BPY_PYTHON to a Python that has it (pip install bpy)")
def test_blender_export_matches_blenders_own_matrix_world(tmp_path):
    proc = subprocess.run([_bpy_python(), str(ROOT / "tools" / "blender_rig.py"), str(tmp_path / "rig.glb"), str(tmp_path / "rig.json")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    from scipy.spatial import cKDTree

    ref = json.loads((tmp_path / "rig.json").read_text())
    (tmp_path / "shot.yaml").write_text("camera: {position: [0, 0, 5], look_at: [0, 0, 0]}\ntimeline: {fps: 24, last: 24}\nimports: [{file: rig.glb}]\n")
    loaded = load_scene(tmp_path / "shot.yaml")
    frames = sorted(int(f) for f in ref["frames"])
    motion = evaluate(loaded, np.array(frames) / 24)
    # Blender is Z-up, glTF Y-up: glTF = C blender C^-1 with (x, y, z) -> (x, z, -y)
    c = np.eye(4)
    c[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]
    for i, f in enumerate(frames):
        r = ref["frames"][str(f)]
        for name in ("Parent", "Child"):
            np.testing.assert_allclose(motion.objects[name].matrices()[i], c @ np.array(r[name]) @ np.linalg.inv(c), atol=1e-5, err_msg=f"{name} at frame {f}")
        pose = motion.objects["Tube.mesh"].matrices()[i]
        local = motion.vertices["Tube.mesh"][i]
        ours = (pose @ np.c_[local, np.ones(len(local))].T).T[:, :3]
        theirs = (c[:3, :3] @ np.array(r["Tube"]).T).T
        # the exporter may split and reorder vertices: compare as point sets both ways
        assert cKDTree(theirs).query(ours)[0].max() < 1e-5 and cKDTree(ours).query(theirs)[0].max() < 1e-5, f"frame {f}"


def test_animation_selection(tmp_path):
    """Disjoint animations (one per object, as Blender exports) all play by default; two
    takes of one node: the first by default, one by name, and '*' is a located error."""
    b = GltfBuilder()
    a, c = b.node(name="A"), b.node(name="C")
    b.gltf["scenes"][0]["nodes"] = [a, c]
    t = b.accessor(np.array([0.0, 1.0]), bounds=True)

    def anim(name, node, y):
        out = b.accessor(np.array([[0, 0, 0], [0, y, 0]], float))
        return {"name": name, "samplers": [{"input": t, "output": out}], "channels": [{"sampler": 0, "target": {"node": node, "path": "translation"}}]}

    b.gltf["animations"] = [anim("MoveA", a, 1.0), anim("MoveC", c, 2.0)]
    b.save(tmp_path / "two.glb")
    cam = "camera: {position: [0, 0, 5], look_at: [0, 0, 0]}"
    motion = evaluate(load_scene(scene_yaml(tmp_path, "two.glb", extra=cam)), np.array([1.0]))
    assert motion.objects["a.A"].translation[0] == pytest.approx([1, 4, 3]) and motion.objects["a.C"].translation[0] == pytest.approx([1, 6, 3])
    b.gltf["animations"] = [anim("Walk", a, 1.0), anim("Run", a, 3.0)]
    b.save(tmp_path / "takes.glb")
    motion = evaluate(load_scene(scene_yaml(tmp_path, "takes.glb", extra=cam)), np.array([1.0]))
    assert motion.objects["a.A"].translation[0] == pytest.approx([1, 4, 3])
    motion = evaluate(load_scene(scene_yaml(tmp_path, "takes.glb", extra=cam, imports_extra="    animation: Run")), np.array([1.0]))
    assert motion.objects["a.A"].translation[0] == pytest.approx([1, 8, 3])
    msg = _one_line_error(scene_yaml(tmp_path, "takes.glb", extra=cam, imports_extra="    animation: '*'"))
    assert "takes.glb: animations[1].channels[0]: node 0 'A' translation is keyed twice (also in animations[0])" in msg


def test_metallic_roughness_texture_splits_into_grey_textures(tmp_path):
    """glTF packs roughness in G and metallic in B; each becomes a raw grey texture with
    its factor multiplied in, which the renderer's principled material accepts."""
    from PIL import Image
    import io

    img = np.zeros((2, 2, 3), np.uint8)
    img[..., 1], img[..., 2] = 200, 100
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    b = GltfBuilder()
    pos = b.accessor(np.eye(3), target="vertex", bounds=True)
    tex = b.image(buf.getvalue())
    b.gltf["materials"] = [{"name": "Metal", "pbrMetallicRoughness": {"metallicFactor": 0.5, "roughnessFactor": 1.0, "metallicRoughnessTexture": {"index": tex}}}]
    b.gltf["meshes"].append({"primitives": [{"attributes": {"POSITION": pos}, "material": 0}]})
    b.gltf["scenes"][0]["nodes"] = [b.node(name="Thing", mesh=0)]
    b.save(tmp_path / "mr.glb")
    loaded = load_scene(scene_yaml(tmp_path, "mr.glb", extra="camera: {position: [0, 0, 5], look_at: [0, 0, 0]}"))
    mat = next(m for m in loaded.scene.materials if m.name == "a.Metal")
    assert mat.roughness.raw and mat.metallic.raw
    assert np.asarray(Image.open(mat.roughness.file)).max() == 200
    assert np.asarray(Image.open(mat.metallic.file)).max() == 50
    from motion.pipeline.render.translate.build import material_dict
    from motion.pipeline.variant import activate

    activate("auto", quiet=True)
    d = material_dict(mat, loaded)
    assert d["roughness"]["type"] == "bitmap" and d["metallic"]["filename"] == mat.metallic.file


def test_second_load_is_warm_and_the_same(asset, tmp_path):
    """The second load reads the cached records and converted files, decoding nothing;
    a changed source file is converted again."""
    from motion.pipeline.scene.imports import converted as cache

    tmp, _, _ = asset
    shutil.copy(tmp / "rig.glb", tmp_path / "rig.glb")
    shot = scene_yaml(tmp_path, "rig.glb")
    before = dict(cache.STATS)
    cold = load_scene(shot).scene
    misses = cache.STATS["misses"] - before["misses"]
    warm = load_scene(shot).scene
    assert cache.STATS["misses"] - before["misses"] == misses  # nothing converted again
    assert cache.STATS["records"] == before["records"] + 1  # the records came from the cache
    assert warm == cold
    data = bytearray((tmp_path / "rig.glb").read_bytes())
    data[-4:] = b"\x00\x00\x80\x3f"  # change the last float of the binary chunk
    (tmp_path / "rig.glb").write_bytes(bytes(data))
    load_scene(shot)
    assert cache.STATS["misses"] > before["misses"] + misses


def test_mutated_files_give_located_errors_never_a_traceback(asset, tmp_path):
    """Random damage to the JSON of a valid asset (wrong types, out-of-range indices,
    deleted keys) is either imported or reported as located lines: never another error."""
    import copy
    import random

    tmp, _, _ = asset
    data = (tmp / "rig.glb").read_bytes()
    n = int.from_bytes(data[12:16], "little")
    doc, blob = json.loads(data[20 : 20 + n]), data[20 + n + 8 :]
    values = [None, -1, 0, 1, 10**9, "x", 3.5, [], {}, [1, 2], True]
    rng = random.Random(15)
    shot = scene_yaml(tmp_path, "m.glb", extra="camera: {position: [0, 0, 5], look_at: [0, 0, 0]}")
    for _ in range(80):
        mutated = copy.deepcopy(doc)
        for _ in range(rng.randint(1, 3)):
            node, path = mutated, []
            while isinstance(node, (dict, list)) and node and rng.random() < 0.8:
                key = rng.choice(list(node)) if isinstance(node, dict) else rng.randrange(len(node))
                path.append((node, key))
                node = node[key]
            if path:
                parent, key = path[-1]
                if rng.random() < 0.2 and isinstance(parent, dict):
                    del parent[key]
                else:
                    parent[key] = rng.choice(values)
        b = GltfBuilder()
        b.gltf, b.blob = mutated, bytearray(blob)
        b.save(tmp_path / "m.glb")
        try:
            evaluate(load_scene(shot), np.array([0.0, 0.3]))
        except SceneError as err:
            assert err.problems and all(p.file.endswith(("m.glb", "shot.yaml")) for p in err.problems), str(err)


def test_kept_gltf_records_follow_the_buffer_file_a_gltf_names(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A .gltf keeps its vertices in a .bin beside it. The records are kept between loads
    (imports/memo.py) by the digest of every file the reader read: a new .bin under the
    same name is read again (a mesh converted from the new vertices), an unchanged one is
    not."""
    import struct

    from motion.pipeline.meshes import load_mesh
    from motion.pipeline.scene.imports import converted as cache

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))

    def write_bin(x: float) -> None:
        (tmp_path / "tri.bin").write_bytes(struct.pack("<9f", 0, 0, 0, x, 0, 0, 0, 1, 0))

    write_bin(1.0)
    doc = {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"name": "Tri", "mesh": 0}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}], "buffers": [{"uri": "tri.bin", "byteLength": 36}],
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [2, 1, 0]}]}
    (tmp_path / "tri.gltf").write_text(json.dumps(doc))
    (tmp_path / "shot.yaml").write_text("camera: {position: [0, 0, 5], look_at: [0, 0, 0]}\nimports: [{file: tri.gltf}]\n")

    def widest() -> float:
        scene = load_scene(tmp_path / "shot.yaml", assets=False).scene
        mesh = next(o for o in scene.objects if o.shape == "mesh")
        return float(load_mesh(Path(mesh.file))[0][:, 0].max())

    before = cache.STATS["records"]
    assert widest() == 1.0
    assert widest() == 1.0 and cache.STATS["records"] == before + 1  # kept
    write_bin(2.0)
    assert widest() == 2.0 and cache.STATS["records"] == before + 1  # read again
    assert widest() == 2.0 and cache.STATS["records"] == before + 2


# --- Khronos BoxAnimated under a non-uniform parent scale -----------------------------------

# The inner box's half extents and the keys of the Khronos sample BoxAnimated
# (glTF-Sample-Models 2.0/BoxAnimated: accessors 2, 6-9), rewritten with our writer.
BOX_HALF = np.array([0.33504000306129458, 0.5, 0.33504000306129458])
BOX_ROTATION_KEYS = ([1.25, 2.5], [[-0.0, -0.0, -0.0, -1.0], [1.0, 0.0, 0.0, 4.4896593387466766e-11]])
BOX_TRANSLATION_KEYS = ([0.0, 1.25, 2.5, 3.708329916000366], [[0, 0, 0], [0, 2.5199999809265137, 0], [0, 2.5199999809265137, 0], [0, 0, 0]])


def build_box_animated(path: Path, root_scale: list[float]) -> tuple[dict, dict]:
    """BoxAnimated's node tree (node 0 > node 1 > node 2 with the inner box; node 3 the
    outer box), its two animations (node 2's rotation, node 0's translation), the edit
    `"scale": root_scale` on node 0; returns the JSON and the accessors' arrays."""
    b = GltfBuilder()
    arrays: dict[int, np.ndarray] = {}

    def acc(a, **kw):
        i = b.accessor(a, **kw)
        arr = np.asarray(a, np.float32).astype(np.float64)
        arrays[i] = arr if arr.ndim == 2 else arr[:, None]
        return i

    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * BOX_HALF
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    inner = acc(corners, target="vertex", bounds=True)
    outer = acc(corners / BOX_HALF * 0.5, target="vertex", bounds=True)
    idx = b.accessor(faces.reshape(-1).astype(np.uint16), dtype="uint16", target="index")
    g = b.gltf
    g["meshes"] = [{"name": "inner_box", "primitives": [{"attributes": {"POSITION": inner}, "indices": idx}]},
                   {"name": "outer_box", "primitives": [{"attributes": {"POSITION": outer}, "indices": idx}]}]
    b.node(children=[1], rotation=[-0.0, -0.0, -0.0, -1.0], scale=root_scale)
    b.node(children=[2])
    b.node(mesh=0, rotation=[-0.0, -0.0, -0.0, -1.0])
    b.node(mesh=1)
    g["scenes"] = [{"nodes": [3, 0]}]
    rt, rv = acc(np.array(BOX_ROTATION_KEYS[0])), acc(np.array(BOX_ROTATION_KEYS[1]))
    tt, tv = acc(np.array(BOX_TRANSLATION_KEYS[0])), acc(np.array(BOX_TRANSLATION_KEYS[1]))
    g["animations"] = [
        {"channels": [{"sampler": 0, "target": {"node": 2, "path": "rotation"}}], "samplers": [{"input": rt, "interpolation": "LINEAR", "output": rv}]},
        {"channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}], "samplers": [{"input": tt, "interpolation": "LINEAR", "output": tv}]},
    ]
    b.save(path)
    # the specification's evaluator above reads one animation: the two, merged
    merged = dict(g, animations=[{
        "channels": [{"sampler": 0, "target": {"node": 2, "path": "rotation"}}, {"sampler": 1, "target": {"node": 0, "path": "translation"}}],
        "samplers": [g["animations"][0]["samplers"][0], g["animations"][1]["samplers"][0]],
    }])
    return merged, arrays


def test_box_animated_under_a_non_uniform_root_scale_matches_the_specification(tmp_path):
    """BoxAnimated with "scale": [1, 2, 1] on its root: at frame 45 (24 fps) the inner box,
    turned 90 degrees about X under the stretched root, spans y 1.85-3.19 and z -0.5..0.5
    (the specification's 4x4 product; Blender's importer agrees); a per-axis product of
    scales gave y 2.185-2.855 and z -1..1. Every sampled time within 1e-4 m of the
    specification's matrices, vertex by vertex."""
    g, arrays = build_box_animated(tmp_path / "BoxAnimated.gltf", [1.0, 2.0, 1.0])
    scene = tmp_path / "shot.yaml"
    scene.write_text(f"name: box\ntimeline: {{fps: {FPS}, first: 0, last: 90}}\nimports:\n  - file: BoxAnimated.gltf\n"
                     "camera: {position: [0, 2, 8], look_at: [0, 2, 0]}\nlights:\n  - {type: constant, radiance: 0.3}\nrender: {resolution: [32, 24], spp: 2}\n")
    loaded = load_scene(scene)
    times = np.array([0.0, 1.0, 1.25, 1.5, 45 / FPS, 2.0, 2.5, 3.0, 3.5])
    motion = evaluate(loaded, times)
    spec = SpecWorld(g, arrays)
    inner = next(o.name for o in loaded.scene.objects if o.name.endswith("node2") or o.name.endswith("node2.inner_box"))
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * BOX_HALF
    ours = motion.objects[inner].transform_points(corners)
    for i, t in enumerate(times):
        expected = (spec.world(2, t) @ np.c_[corners, np.ones(8)].T).T[:, :3]
        np.testing.assert_allclose(ours[i], expected, atol=1e-4, err_msg=f"t={t}")
    at45 = ours[list(times).index(45 / FPS)]
    np.testing.assert_allclose([at45[:, 1].min(), at45[:, 1].max()], [2.52 - 2 * BOX_HALF[0], 2.52 + 2 * BOX_HALF[0]], atol=1e-4)  # 1.85, 3.19
    np.testing.assert_allclose([at45[:, 2].min(), at45[:, 2].max()], [-0.5, 0.5], atol=1e-4)
