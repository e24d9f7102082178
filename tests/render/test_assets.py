"""Deforming geometry (render/translate/deforming.py) against Mitsuba's own `path` on the same asset
written by hand: texture coordinates from the file, smooth normals, emission, emissive
particles. The method of the light tests (tests/render/test_correctness.py): the
reference never goes through our builders, and |ours - ref| is judged against the noise
floor |ref(seed a) - ref(seed b)|. Frames 0 (cold) and 1 (warm) are both checked."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from _light_scenes import light_scene_yaml, reference_scene
from _render_support import activate, load, render

pytestmark = pytest.mark.render

SPP = 48
RES = (48, 36)
CENTRE = [0.0, 1.3, 0.0]
# a one-key blend shape: the mesh deforms into itself, so it renders through the slices
DEFORM = "deform: {type: blend-shapes, keys: [{time: 0, file: ball.obj}]}"


def _write_ball(tmp_path: Path, nu: int = 12, nv: int = 7, normals: bool = True, name: str = "ball.obj") -> None:
    """A UV sphere of radius 1.3 as OBJ: positions welded at the seam and the poles, one
    `vt` per grid corner (a seam in uv), `vn` the exact sphere normals (none without
    `normals`); and a checker."""
    import mitsuba as mi

    positions: list[list[float]] = []
    index: dict[tuple[int, int], int] = {}  # (column mod nu, row) -> 1-based OBJ vertex
    for j in range(nv + 1):
        for i in range(1 if j in (0, nv) else nu):
            th, ph = np.pi * j / nv, 2 * np.pi * i / nu
            positions.append([np.sin(th) * np.cos(ph), np.cos(th), np.sin(th) * np.sin(ph)])
            index[(i, j)] = len(positions)
    out = [f"v {' '.join(f'{1.3 * c:.6f}' for c in n)}" for n in positions]
    out += [f"vn {' '.join(f'{c:.6f}' for c in n)}" for n in positions] if normals else []
    out += [f"vt {i / nu:.6f} {1 - j / nv:.6f}" for j in range(nv + 1) for i in range(nu + 1)]

    def corner(i: int, j: int) -> str:
        p = index[(0 if j in (0, nv) else i % nu, j)]
        return f"{p}/{j * (nu + 1) + i + 1}" + (f"/{p}" if normals else "")

    for j in range(nv):
        for i in range(nu):
            quad = [corner(i, j), corner(i + 1, j), corner(i + 1, j + 1), corner(i, j + 1)]  # outward
            if j == 0:
                quad = quad[:1] + quad[2:]
            elif j == nv - 1:
                quad = quad[:3]
            out.append("f " + " ".join(quad))
    (tmp_path / name).write_text("\n".join(out) + "\n")
    checker = np.indices((8, 8)).sum(axis=0) % 2
    rgb = np.where(checker[..., None] == 1, [0.9, 0.8, 0.1], [0.1, 0.2, 0.7]).astype(np.float32)
    mi.Bitmap(rgb).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, True).write(str(tmp_path / "checker.png"))


def _ball_yaml(material: str, extra: str = "", face_normals: bool = True) -> str:
    return (
        f"  - {{name: ball, shape: mesh, file: ball.obj, material: {material}, face_normals: {str(face_normals).lower()}, "
        f"transform: {{translate: {CENTRE}}}, {DEFORM}{extra}}}\n"
    )


def _ball_ref(tmp_path: Path, bsdf: dict[str, Any], face_normals: bool = True, emitter: dict[str, Any] | None = None) -> dict[str, Any]:
    import mitsuba as mi

    d = {"type": "obj", "filename": str(tmp_path / "ball.obj"), "face_normals": face_normals, "bsdf": bsdf, "to_world": mi.ScalarTransform4f().translate(CENTRE)}
    if emitter is not None:
        d["emitter"] = emitter
    return {"ball": d}


def _checker_ref(tmp_path: Path) -> dict[str, Any]:
    return {"type": "diffuse", "reflectance": {"type": "bitmap", "filename": str(tmp_path / "checker.png"), "filter_type": "nearest"}}


MATERIALS = "  - {name: chk, type: diffuse, color: {file: checker.png, filter: nearest}}\n  - {name: grey, type: diffuse, color: 0.6}\n  - {name: gold, type: conductor, preset: Au, roughness: 0.3}\n"

# id -> (lights YAML, objects YAML, reference (emitters, shapes) from tmp_path)
CASES: dict[str, tuple[str, str, Any]] = {
    "deforming-textured": (
        "  - {type: directional, direction: [-0.3, -1, -0.5], irradiance: 2.0}\n  - {type: constant, radiance: 0.3}",
        _ball_yaml("chk"),
        lambda p: (
            {"sun": {"type": "directional", "direction": [-0.3, -1, -0.5], "irradiance": 2.0}, "sky": {"type": "constant", "radiance": 0.3}},
            _ball_ref(p, _checker_ref(p)),
        ),
    ),
    "deforming-smooth-normals": (
        "  - {type: directional, direction: [-0.3, -1, -0.5], irradiance: 2.0}\n  - {type: constant, radiance: 0.3}",
        _ball_yaml("gold", face_normals=False),
        lambda p: (
            {"sun": {"type": "directional", "direction": [-0.3, -1, -0.5], "irradiance": 2.0}, "sky": {"type": "constant", "radiance": 0.3}},
            _ball_ref(p, {"type": "roughconductor", "material": "Au", "alpha": 0.09, "distribution": "ggx"}, face_normals=False),
        ),
    ),
    "deforming-emissive": (
        "  - {type: constant, radiance: 0.05}",
        _ball_yaml("grey", ", emission: {radiance: [3.0, 2.0, 1.0]}"),
        lambda p: (
            {"sky": {"type": "constant", "radiance": 0.05}},
            _ball_ref(p, {"type": "diffuse", "reflectance": 0.6}, emitter={"type": "area", "radiance": {"type": "rgb", "value": [3.0, 2.0, 1.0]}}),
        ),
    ),
}


def _agree(ours: np.ndarray, scene: Any, case: str) -> None:
    import mitsuba as mi

    ref_a = np.array(mi.render(scene, seed=31, spp=SPP))[..., :3]
    ref_b = np.array(mi.render(scene, seed=32, spp=SPP))[..., :3]
    floor = np.abs(ref_a - ref_b).mean()
    err = np.abs(ours - ref_a).mean()
    assert np.isfinite(ours).all()
    assert err < 1.3 * floor, (case, err, floor, ours.mean(), ref_a.mean())
    assert ours.mean() == pytest.approx(ref_a.mean(), rel=0.03), case
    assert ref_a.std() > 0.02  # a lit picture, not two dark images agreeing


@pytest.mark.parametrize("case", list(CASES))
def test_deforming_asset_agrees_with_mitsuba_path(tmp_path: Path, case: str) -> None:
    """A deforming OBJ (one-key blend shape) with `vt`/`vn`, textured, smooth or emissive:
    ours (cold and warm) against the same OBJ loaded by Mitsuba itself."""
    activate()
    import mitsuba as mi

    _write_ball(tmp_path)
    lights, objects, reference = CASES[case]
    text = light_scene_yaml(lights, objects, resolution=RES, spp=SPP, last=1).replace("materials:\n", "materials:\n" + MATERIALS)
    loaded = load(tmp_path, text)
    images, stats, renderer = render(loaded, [0, 1])
    assert renderer.deforming_names == ("ball",)  # in the one traversal, emissive or not
    # an emissive one is light-sampled from its templates in the atlas (kernel/lights.py)
    assert (renderer.cache.integrator.world.emitters is not None) == (case == "deforming-emissive")
    assert [s.cold for s in stats] == [True, False]
    emitters, shapes = reference(tmp_path)
    scene = reference_scene(mi, emitters, shapes, resolution=RES, spp=SPP)
    for image in images:
        _agree(image[..., :3], scene, case)


def test_emissive_particles_agree_with_mitsuba_path(tmp_path: Path) -> None:
    """Emissive particles (spheres in the one traversal) light the floor and glow: against
    the same spheres (at the baked positions) as emissive spheres in Mitsuba's `path`."""
    activate()
    import mitsuba as mi

    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.render.poses.stacked import stack_frame

    objects = (
        "  - {name: sparks, shape: particles, radius: 0.12, material: black, emission: {radiance: [6.0, 4.0, 2.0]}, "
        "emitter: {rate: 240, lifetime: 5, position: [0, 0.6, 0], size: [1.6, 0.6, 1.2], speed: 0, seed: 3}}\n"
    )
    text = light_scene_yaml("  - {type: constant, radiance: 0.05}", objects, resolution=RES, spp=SPP, last=1)
    loaded = load(tmp_path, text)
    images, _, _ = render(loaded, [1])
    (fi,) = evaluate_frames(loaded, [1])
    positions, alive = stack_frame(fi).particles["sparks"]
    count = int(alive[0].sum())
    assert count >= 5
    shapes = {
        f"spark{k}": {"type": "sphere", "center": [float(c) for c in p], "radius": 0.12, "bsdf": {"type": "diffuse", "reflectance": 0.0},
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [6.0, 4.0, 2.0]}}}
        for k, p in enumerate(positions[0][alive[0]])
    }
    scene = reference_scene(mi, {"sky": {"type": "constant", "radiance": 0.05}}, shapes, resolution=RES, spp=SPP)
    _agree(images[0][..., :3], scene, "emissive-particles")


# --- materials as the file says: normal maps, opacity masks, thin panes -------------------

CARD = {"translate": [0.0, 1.0, 1.0], "angle": -45.0, "size": (2.4, 1.6)}
SUN = ("  - {type: directional, direction: [-0.3, -1, -0.5], irradiance: 2.0}\n  - {type: constant, radiance: 0.3}",
       {"sun": {"type": "directional", "direction": [-0.3, -1, -0.5], "irradiance": 2.0}, "sky": {"type": "constant", "radiance": 0.3}})


def _write_maps(tmp_path: Path) -> None:
    """ripple.png: a tangent-space normal map of ripples along u; holes.png: a 0/1 checker."""
    import mitsuba as mi

    u = (np.arange(64) + 0.5) / 64
    slope = 2.0 * np.cos(2 * np.pi * 2 * u)
    n = np.stack([-slope, np.zeros_like(u), np.ones_like(u)], axis=1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    rgb = np.broadcast_to(((n + 1) / 2)[None], (64, 64, 3)).astype(np.float32)
    mi.Bitmap(np.ascontiguousarray(rgb)).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, False).write(str(tmp_path / "ripple.png"))
    holes = (np.indices((6, 6)).sum(axis=0) % 2).astype(np.float32)[..., None]
    mi.Bitmap(np.ascontiguousarray(holes)).convert(mi.Bitmap.PixelFormat.Y, mi.Struct.Type.UInt8, False).write(str(tmp_path / "holes.png"))


def _card_yaml(material: str) -> str:
    w, h = CARD["size"]
    return f"  - {{name: card, shape: rectangle, width: {w}, height: {h}, material: {material}, transform: {{translate: {CARD['translate']}, rotate: {{euler: [{CARD['angle']}, 0, 0]}}}}}}\n"


def _card_ref(bsdf: dict[str, Any]) -> dict[str, Any]:
    import mitsuba as mi

    T = mi.ScalarTransform4f
    w, h = CARD["size"]
    return {"card": {"type": "rectangle", "bsdf": bsdf, "to_world": T().translate(CARD["translate"]) @ T().rotate([1, 0, 0], CARD["angle"]) @ T().scale([w / 2, h / 2, 1])}}


def _bitmap(path: Path, **extra: Any) -> dict[str, Any]:
    return {"type": "bitmap", "filename": str(path), "raw": True, **extra}


# id -> (material YAML line, reference BSDF from tmp_path)
MATERIAL_CASES: dict[str, tuple[str, Any]] = {
    "normal-mapped": (
        "  - {name: m, type: plastic, color: [0.6, 0.5, 0.3], roughness: 0.2, normal_map: {file: ripple.png}}\n",
        lambda p: {"type": "normalmap", "normalmap": _bitmap(p / "ripple.png"),
                   "bsdf": {"type": "roughplastic", "alpha": 0.04, "distribution": "ggx", "diffuse_reflectance": {"type": "rgb", "value": [0.6, 0.5, 0.3]}, "int_ior": 1.49}},
    ),
    "masked": (
        "  - {name: m, type: diffuse, color: [0.2, 0.6, 0.3], opacity: {file: holes.png, filter: nearest}}\n",
        lambda p: {"type": "mask", "opacity": _bitmap(p / "holes.png", filter_type="nearest"), "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.6, 0.3]}}},
    ),
    "textured-conductor-tint": (
        "  - {name: m, type: conductor, preset: none, tint: {file: colour.png, filter: nearest}}\n",
        lambda p: {"type": "conductor", "material": "none", "specular_reflectance": {"type": "bitmap", "filename": str(p / "colour.png"), "filter_type": "nearest"}},
    ),
    "roughness-texture": (
        "  - {name: m, type: conductor, preset: Au, roughness: {file: rough.png, raw: true, filter: nearest}}\n",
        lambda p: {"type": "roughconductor", "material": "Au", "distribution": "ggx", "alpha": {"type": "bitmap", "filename": str(p / "alpha.exr"), "filter_type": "nearest"}},
    ),
    "thin-dielectric": (
        "  - {name: m, type: thindielectric, ior: 1.5}\n",
        lambda p: {"type": "thindielectric", "int_ior": 1.5},
    ),
}


@pytest.mark.parametrize("case", list(MATERIAL_CASES))
def test_material_agrees_with_mitsuba_path(tmp_path: Path, case: str) -> None:
    """A tilted card of each material over the ball and floor, in the sun: ours against the
    same card with Mitsuba's own plugins written by hand."""
    activate()
    import mitsuba as mi

    from _light_scenes import BALL, ball_shape

    _write_card_images(tmp_path)
    material, reference = MATERIAL_CASES[case]
    text = light_scene_yaml(SUN[0], BALL + _card_yaml("m"), resolution=RES, spp=SPP, last=1).replace("materials:\n", "materials:\n" + material)
    images, _, _ = render(load(tmp_path, text), [0])
    scene = reference_scene(mi, SUN[1], {**ball_shape(mi), **_card_ref(reference(tmp_path))}, resolution=RES, spp=SPP)
    _agree(images[0][..., :3], scene, case)


@pytest.mark.parametrize("kind", ["dielectric", "thindielectric"])
def test_two_sided_transmissive_material_is_refused_at_validation(tmp_path: Path, kind: str) -> None:
    """`two_sided` on glass means nothing (Mitsuba's twosided refuses transmissive BSDFs,
    which used to fail every frame): a located error before any task; on a diffuse it
    is accepted."""
    from motion.pipeline.errors import SceneError

    base = light_scene_yaml("  - {type: constant, radiance: 0.3}", "", resolution=RES, spp=SPP)
    pane = base.replace("color: 0.0}\n", f"color: 0.0}}\n  - {{name: pane, type: {kind}, two_sided: true}}\n")
    with pytest.raises(SceneError, match=r"materials\[3\]\.two_sided.*transmissive"):
        load(tmp_path, pane)
    assert load(tmp_path, base.replace("color: 0.0}", "color: 0.0, two_sided: true}")).scene.materials[2].two_sided


# --- imported materials: glTF metallic-roughness and UsdPreviewSurface in full -------------

W, H = CARD["size"]
QUAD = np.array([[-W / 2, -H / 2, 0], [W / 2, -H / 2, 0], [W / 2, H / 2, 0], [-W / 2, H / 2, 0]])
QUAD_UV = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], float)  # Mitsuba's (and glTF's) uv: v = 0 at the image's top
QUAD_TRI = np.array([[0, 1, 2], [0, 2, 3]])


def _write_card_images(tmp_path: Path) -> dict[str, bytes]:
    """colour.png (RGB checker; colour_a.png the same with the holes as alpha), glow.png,
    plus ripple.png and holes.png (`_write_maps`): returns the PNG bytes by name."""
    import mitsuba as mi

    _write_maps(tmp_path)
    cells = np.indices((64, 64)) // 16
    rgb = np.where(((cells[0] + cells[1]) % 2 == 1)[..., None], [0.85, 0.7, 0.2], [0.2, 0.35, 0.8]).astype(np.float32)
    mi.Bitmap(rgb).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, True).write(str(tmp_path / "colour.png"))
    holes = np.array(mi.Bitmap(str(tmp_path / "holes.png")), dtype=np.float32).reshape(6, 6)
    alpha = np.repeat(np.repeat(holes, 11, axis=0), 11, axis=1)[:64, :64, None]
    rgba = np.concatenate([np.array(mi.Bitmap(str(tmp_path / "colour.png")), dtype=np.float32) / 255, alpha], axis=2)
    mi.Bitmap(np.ascontiguousarray(rgba), mi.Bitmap.PixelFormat.RGBA).convert(mi.Bitmap.PixelFormat.RGBA, mi.Struct.Type.UInt8, False).write(str(tmp_path / "colour_a.png"))
    mi.Bitmap(np.ascontiguousarray(alpha)).convert(mi.Bitmap.PixelFormat.Y, mi.Struct.Type.UInt8, False).write(str(tmp_path / "holes64.png"))
    glow = np.zeros((8, 8, 3), np.float32)
    glow[2:6, 1:7] = [1.0, 0.6, 0.3]
    mi.Bitmap(glow).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, True).write(str(tmp_path / "glow.png"))
    # roughness 0.2 / 0.8 in a checker, and (for the reference, written here) its GGX alpha
    rough = np.where((cells[0] + cells[1]) % 2 == 1, 0.2, 0.8).astype(np.float32)[..., None]
    mi.Bitmap(np.ascontiguousarray(rough)).convert(mi.Bitmap.PixelFormat.Y, mi.Struct.Type.UInt8, False).write(str(tmp_path / "rough.png"))
    stored = np.array(mi.Bitmap(str(tmp_path / "rough.png")), dtype=np.float32) / 255
    mi.Bitmap(np.ascontiguousarray(stored**2)).write(str(tmp_path / "alpha.exr"))
    return {n: (tmp_path / n).read_bytes() for n in ("colour.png", "colour_a.png", "ripple.png", "glow.png", "holes64.png")}


def _card_reference(tmp_path: Path, holes: str) -> dict[str, Any]:
    """The imported card written by hand: the quad with its uvs, principled under Mitsuba's
    normalmap, an opacity mask and a textured area emitter."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    mesh = mi.Mesh("card", 4, 2, mi.Properties(), False, True)
    p = mi.traverse(mesh)
    p["vertex_positions"] = mi.Float(QUAD.astype(np.float32).ravel())
    p["vertex_texcoords"] = mi.Float(QUAD_UV.astype(np.float32).ravel())
    p["faces"] = mi.UInt32(QUAD_TRI.astype(np.uint32).ravel())
    p.update()
    mesh.write_ply(str(tmp_path / "card_ref.ply"))
    principled = {"type": "principled", "base_color": {"type": "bitmap", "filename": str(tmp_path / "colour.png")}, "metallic": 0.0, "roughness": 0.6, "specular": 0.5, "clearcoat": 0.0}
    bsdf = {"type": "mask", "opacity": _bitmap(tmp_path / holes), "bsdf": {"type": "normalmap", "normalmap": _bitmap(tmp_path / "ripple.png"), "bsdf": principled}}
    return {"card": {"type": "ply", "filename": str(tmp_path / "card_ref.ply"), "bsdf": bsdf, "emitter": {"type": "area", "radiance": {"type": "bitmap", "filename": str(tmp_path / "glow.png")}},
                     "to_world": T().translate(CARD["translate"]) @ T().rotate([1, 0, 0], CARD["angle"])}}


def _gltf_card(tmp_path: Path, images: dict[str, bytes], normal_scale: float = 1.0, alpha_mode: str = "MASK", alpha: float = 1.0) -> str:
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
    from gltf_writer import GltfBuilder

    b = GltfBuilder()
    g = b.gltf
    attrs = {"POSITION": b.accessor(QUAD, target="vertex", bounds=True), "NORMAL": b.accessor(np.tile([0.0, 0, 1], (4, 1)), target="vertex"), "TEXCOORD_0": b.accessor(QUAD_UV, target="vertex")}
    tex = {n: b.image(images[n]) for n in ("colour_a.png", "ripple.png", "glow.png")}
    g["materials"] = [{
        "name": "Card",
        "pbrMetallicRoughness": {"baseColorTexture": {"index": tex["colour_a.png"]}, "baseColorFactor": [1.0, 1.0, 1.0, alpha], "metallicFactor": 0.0, "roughnessFactor": 0.6},
        "normalTexture": {"index": tex["ripple.png"], "scale": normal_scale},
        "emissiveTexture": {"index": tex["glow.png"]},
        "emissiveFactor": [1.0, 1.0, 1.0],
        "alphaMode": alpha_mode,
        "alphaCutoff": 0.5,
    }]
    g["meshes"].append({"name": "Card", "primitives": [{"attributes": attrs, "indices": b.accessor(QUAD_TRI.ravel(), dtype="uint32", target="index"), "material": 0}]})
    g["scenes"][0]["nodes"] = [b.node(name="Card", mesh=0)]
    b.save(tmp_path / "card.glb")
    return "card.glb"


def _usd_card(tmp_path: Path, images: dict[str, bytes]) -> str:
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade

    stage = Usd.Stage.CreateNew(str(tmp_path / "card.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    mesh = UsdGeom.Mesh.Define(stage, "/Card")
    mesh.GetPointsAttr().Set([Gf.Vec3f(*p) for p in QUAD])
    mesh.GetFaceVertexCountsAttr().Set([4])
    mesh.GetFaceVertexIndicesAttr().Set([0, 1, 2, 3])
    st = UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
    st.Set([Gf.Vec2f(u, 1 - v) for u, v in QUAD_UV])  # USD's st: t = 0 at the image's bottom
    mat = UsdShade.Material.Define(stage, "/Looks/Card")
    surface = UsdShade.Shader.Define(stage, "/Looks/Card/Surface")
    surface.CreateIdAttr("UsdPreviewSurface")
    surface.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
    surface.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.6)
    surface.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(0.5)

    def texture(name: str, file: str, output: str, raw: bool, kind: Any) -> None:
        tex = UsdShade.Shader.Define(stage, f"/Looks/Card/{name}")
        tex.CreateIdAttr("UsdUVTexture")
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(file)
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("raw" if raw else "sRGB")
        out = tex.CreateOutput(output, kind)
        surface.CreateInput(name, kind).ConnectToSource(out)

    texture("diffuseColor", "colour.png", "rgb", False, Sdf.ValueTypeNames.Color3f)
    texture("normal", "ripple.png", "rgb", True, Sdf.ValueTypeNames.Normal3f)
    texture("opacity", "holes64.png", "r", True, Sdf.ValueTypeNames.Float)
    texture("emissiveColor", "glow.png", "rgb", False, Sdf.ValueTypeNames.Color3f)
    mat.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(mat)
    stage.GetRootLayer().Save()
    return "card.usda"


@pytest.mark.parametrize("kind", ["gltf", "usd"])
def test_imported_material_agrees_with_mitsuba_path(tmp_path: Path, kind: str) -> None:
    """A card imported from glTF (baseColor with alpha MASK, metallic-roughness factors,
    normal and emissive textures) or USD (UsdPreviewSurface with diffuse, normal, opacity
    and emissive textures): ours against the same card written in Mitsuba's own terms."""
    if kind == "usd":
        pytest.importorskip("pxr", reason="usd-core is not installed")
    activate()
    import mitsuba as mi

    from _light_scenes import BALL, ball_shape

    images = _write_card_images(tmp_path)
    file = _gltf_card(tmp_path, images) if kind == "gltf" else _usd_card(tmp_path, images)
    imports = f"imports:\n  - {{file: {file}, transform: {{translate: {CARD['translate']}, rotate: {{euler: [{CARD['angle']}, 0, 0]}}}}}}\n"
    text = imports + light_scene_yaml(SUN[0], BALL, resolution=RES, spp=SPP, last=1)
    images_out, _, _ = render(load(tmp_path, text), [0])
    reference = _card_reference(tmp_path, "holes64.png")
    scene = reference_scene(mi, SUN[1], {**ball_shape(mi), **reference}, resolution=RES, spp=SPP)
    _agree(images_out[0][..., :3], scene, kind)


def test_slice_normals_follow_the_deformation(tmp_path: Path) -> None:
    """A deformation that turns the ball 90 degrees about Z turns its file normals with it
    (to 1e-6); unturned they are the file's own (the file's exact sphere normals on a 12 x 7
    ball, not what Mitsuba would compute from the faces); a vertex whose frame degenerates
    (its neighbour moved onto it) keeps a unit normal turned like its neighbours'."""
    activate()
    from motion.pipeline.meshes import load_mesh, load_render_mesh
    from motion.pipeline.render.translate.deforming import neighbours, rest_normals, slice_normals

    _write_ball(tmp_path)
    verts, _ = load_mesh(tmp_path / "ball.obj")
    mesh = load_render_mesh(tmp_path / "ball.obj")
    rest = rest_normals(verts, mesh, np.ones(3))
    assert rest is not None
    file_n = mesh.normals / np.linalg.norm(mesh.normals, axis=1, keepdims=True)
    np.testing.assert_allclose(slice_normals(verts, rest, mesh), file_n, atol=1e-9)
    assert np.abs(_mitsuba_normals(verts[mesh.index], mesh.faces) - file_n).max() > 1e-3  # the file's, not recomputed
    turn = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    np.testing.assert_allclose(slice_normals(verts @ turn.T, rest, mesh), file_n @ turn.T, atol=1e-6)
    v = 20  # an equator vertex: collapse its neighbour onto it, then turn everything
    squashed = verts.copy()
    squashed[neighbours(mesh, len(verts))[v]] = verts[v]
    got = slice_normals(squashed @ turn.T, rest, mesh)
    np.testing.assert_allclose(np.linalg.norm(got, axis=1), 1.0, atol=1e-9)
    mine = mesh.index == v
    assert np.degrees(np.arccos(np.clip(got[mine] @ (file_n[mine] @ turn.T)[0], -1, 1))).max() < 15.0


def _mitsuba_normals(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Mitsuba's own vertex normals [R, 3] of a mesh (`Mesh.recompute_vertex_normals`)."""
    import mitsuba as mi

    mesh = mi.Mesh("probe", len(positions), len(faces), mi.Properties(), True, False)
    p = mi.traverse(mesh)
    p["vertex_positions"] = mi.Float(np.asarray(positions, np.float32).ravel())
    p["faces"] = mi.UInt32(np.asarray(faces, np.uint32).ravel())
    p.update()
    mesh.recompute_vertex_normals()
    return np.array(mi.traverse(mesh)["vertex_normals"], dtype=np.float64).reshape(-1, 3)


@pytest.mark.parametrize("normals", [False, True], ids=["no-file-normals", "file-normals"])
def test_deforming_slice_normals_are_mitsubas_own(tmp_path: Path, normals: bool) -> None:
    """One computation of vertex normals: every slice of a one-key blend shape (the mesh
    at rest) holds the normals Mitsuba's own OBJ reader gives the static mesh, to float
    rounding - Mitsuba's (angle-weighted, creased at the uv seam and the poles as its render
    vertices are) without `vn`, the file's with it. Cold and warm frames alike."""
    activate()
    import mitsuba as mi

    _write_ball(tmp_path, normals=normals)
    text = light_scene_yaml("  - {type: constant, radiance: 0.3}", _ball_yaml("gold", face_normals=False), resolution=(8, 6), spp=1, last=1)
    _, _, renderer = render(load(tmp_path, text.replace("materials:\n", "materials:\n" + MATERIALS)), [0, 1])
    static = mi.traverse(mi.load_dict({"type": "obj", "filename": str(tmp_path / "ball.obj"), "to_world": mi.ScalarTransform4f().translate(CENTRE)}))
    want_p, want_n = (np.array(static[k]).reshape(-1, 3) for k in ("vertex_positions", "vertex_normals"))
    for positions, got_n in _templates(mi, renderer):
        np.testing.assert_allclose(positions, want_p, atol=1e-5)
        np.testing.assert_allclose(got_n, want_n, atol=1e-6)


def _templates(mi: Any, renderer: Any) -> list[tuple[np.ndarray, np.ndarray]]:
    """The one deforming mesh's templates as the atlas holds them, moved to world space by
    its fitted track (the mesh stands still: every row of the track is the same pose):
    (positions, normals) per template."""
    from motion.pipeline.motion.pose import quat_rotate

    cache = renderer.cache
    (g,) = cache.deforming.meshes
    params = mi.traverse(cache.atlas.scene)
    first = cache._deforming_first()
    t, q = g.track[0][0, 0], g.track[1][0, 0]  # its one mover, at the frame's time
    out = []
    for s in range(cache.deforming.slices):
        key = cache.atlas.keys[first + s]
        rest = np.array(params[f"{key}__0.vertex_positions"], dtype=float).reshape(-1, 3) - cache.atlas.layout.offset[first + s]
        normals = np.array(params[f"{key}__0.vertex_normals"], dtype=float).reshape(-1, 3)
        out.append((quat_rotate(q, rest) + t, quat_rotate(q, normals)))
    return out


def test_vertex_normals_are_mitsubas(tmp_path: Path) -> None:
    """`slices.vertex_normals` is Mitsuba's `recompute_vertex_normals` to float rounding:
    on the 12 x 7 ball without `vn` (a uv seam and poles of many render vertices), on a
    stretched 64 x 32 one, and on a mesh with a collinear face and a vertex in no face of
    area (Mitsuba's (1, 0, 0))."""
    activate()
    from motion.pipeline.meshes import load_mesh, load_render_mesh
    from motion.pipeline.meshes import vertex_normals

    for nu, nv, stretch in ((12, 7, 1.0), (64, 32, 3.0)):
        _write_ball(tmp_path, nu, nv, normals=False)
        verts, _ = load_mesh(tmp_path / "ball.obj")
        mesh = load_render_mesh(tmp_path / "ball.obj")
        p = (verts[mesh.index] * [stretch, 1.0, 1.0] + CENTRE).astype(np.float32)
        np.testing.assert_allclose(vertex_normals(p, mesh.faces), _mitsuba_normals(p, mesh.faces), atol=1e-6)
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [2, 0, 0]], np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [0, 1, 4]])
    np.testing.assert_allclose(vertex_normals(p, faces), _mitsuba_normals(p, faces), atol=1e-6)


@pytest.mark.parametrize("normals", [False, True], ids=["no-file-normals", "file-normals"])
def test_a_static_mesh_gets_the_engines_normals_from_the_asset_cache(tmp_path: Path, normals: bool) -> None:
    """One computation of vertex normals for static and deforming meshes: the converted PLY
    of a mesh without `vn` holds `meshes.vertex_normals` of its own vertices, bit for bit
    (what a deforming mesh's slices hold; Mitsuba's PLY reader normalises them once more on
    load, a last-bit change), which is Mitsuba's scheme to float rounding; a mesh with `vn`
    keeps the file's. (Before: the normals Mitsuba's reader computed, whose
    atomic sum varies with the thread count on large meshes.)"""
    activate()
    import mitsuba as mi

    from motion.pipeline.meshes import load_render_mesh, vertex_normals
    from motion.pipeline.render.translate.assets import mesh_file

    _write_ball(tmp_path, 24, 12, normals=normals)
    ply = mesh_file(tmp_path / "ball.obj")
    converted = mi.traverse(mi.load_dict({"type": "ply", "filename": str(ply)}))
    positions = np.array(converted["vertex_positions"], dtype=np.float32).reshape(-1, 3)
    faces = np.array(converted["faces"], dtype=np.int64).reshape(-1, 3)
    got = np.array(converted["vertex_normals"], dtype=np.float32).reshape(-1, 3)
    if normals:
        file_n = load_render_mesh(tmp_path / "ball.obj").normals
        np.testing.assert_allclose(got, file_n / np.linalg.norm(file_n, axis=1, keepdims=True), atol=1e-6)
    else:
        ours = vertex_normals(positions, faces).astype(np.float32)
        np.testing.assert_array_equal(load_render_mesh(ply).normals, ours)  # the file holds ours, bit for bit
        np.testing.assert_allclose(got, ours, atol=2.5e-7)
        np.testing.assert_allclose(got, _mitsuba_normals(positions, faces), atol=1e-6)


def test_deforming_slice_normals_do_not_depend_on_the_thread_count(tmp_path: Path) -> None:
    """Frames are bit-identical whatever the thread count (docs/rendering.md,
    Determinism): so are a 65k-triangle deforming mesh's slice normals, with 1, 2, 4 and 8
    drjit threads, three times over. (Mitsuba's own recompute, an atomic scatter-add, differed
    between such runs in 146 to 2510 components, by up to 1.8e-7.)"""
    activate()
    import drjit as dr
    import mitsuba as mi

    from motion.pipeline.bake import evaluate_frames
    from motion.pipeline.render.poses.stacked import stack_frame

    _write_ball(tmp_path, 256, 128, normals=False)
    text = light_scene_yaml("  - {type: constant, radiance: 0.3}", _ball_yaml("gold", face_normals=False), resolution=(8, 6), spp=1, last=0)
    loaded = load(tmp_path, text.replace("materials:\n", "materials:\n" + MATERIALS).replace("motion_blur: off}", "motion_blur: off, time_slices: 1}"))
    _, _, renderer = render(loaded, [0])
    (fi,) = (stack_frame(f) for f in evaluate_frames(loaded, [0]))
    cache = renderer.cache
    threads = dr.thread_count()
    seen = []
    try:
        for count in (1, 2, 4, 8) * 3:  # each a warm frame's update
            dr.set_thread_count(count)
            cache._draw_deforming(fi, "stochastic", None)
            seen.append(np.array(mi.traverse(cache.atlas.scene)[f"{cache.atlas.keys[cache._deforming_first()]}__0.vertex_normals"]))
    finally:
        dr.set_thread_count(threads)
    for normals in seen[1:]:
        assert np.array_equal(normals, seen[0])


# a rough copper and a rough plastic ball without file normals (one-key blend shape), by
# 8 x 8 blocks against `path` on the static OBJ: ours was |z| 10-11 with our own
# area-weighted, seam-welded normals, 3.3 with Mitsuba's (threshold 6)
ROUGH = {
    "copper": ("{name: shiny, type: conductor, preset: Cu, roughness: 0.3}", {"type": "roughconductor", "material": "Cu", "alpha": 0.09, "distribution": "ggx"}),
    "plastic": ("{name: shiny, type: plastic, color: [0.2, 0.4, 0.8], roughness: 0.3}",
                {"type": "roughplastic", "diffuse_reflectance": {"type": "rgb", "value": [0.2, 0.4, 0.8]}, "alpha": 0.09, "distribution": "ggx", "int_ior": 1.49}),
}


@pytest.mark.parametrize("case", list(ROUGH))
def test_deforming_rough_ball_agrees_with_path_block_by_block(tmp_path: Path, case: str) -> None:
    """A one-key blend shape of a ball without `vn` (rough copper, rough plastic): every
    8 x 8 block of our frame agrees with Mitsuba's `path` on the static OBJ within noise
    (pipeline/compare's block test, the gaussian filter's kappa), not just the mean."""
    activate()
    import mitsuba as mi

    from motion.pipeline.compare.stats import FILTER_KAPPA, compare_frame

    res, spp = (128, 96), 128
    material, bsdf = ROUGH[case]
    _write_ball(tmp_path, normals=False)
    sun = ("  - {type: directional, direction: [-0.3, -1, -0.5], irradiance: 2.0}\n  - {type: constant, radiance: 0.3}",
           {"sun": {"type": "directional", "direction": [-0.3, -1, -0.5], "irradiance": 2.0}, "sky": {"type": "constant", "radiance": 0.3}})
    text = light_scene_yaml(sun[0], _ball_yaml("shiny", face_normals=False), resolution=res, spp=spp, last=0)
    (ours,), _, _ = render(load(tmp_path, text.replace("materials:\n", f"materials:\n  - {material}\n")), [0])
    scene = reference_scene(mi, sun[1], _ball_ref(tmp_path, bsdf, face_normals=False), resolution=res, spp=spp)
    ref = np.array(mi.render(scene, seed=31, spp=spp))[..., :3]
    test = compare_frame(ours[..., :3].astype(np.float32), ref, block=8, kappa=FILTER_KAPPA["gaussian"])
    assert test.verdict == "equal", (case, test.max_z, [r.describe() for r in test.regions])
    assert float(test.z_blocks.max()) < test.threshold
    ball = ref[15:55, 44:84]
    assert ball.std() > 0.02 and ref.std() > 0.02  # a lit ball, not two dark images agreeing


def test_gltf_normal_texture_scale_is_baked_into_the_map(tmp_path: Path) -> None:
    """glTF's normalTexture.scale bends the map's x and y: the imported normal map holds
    normalize((2c - 1) (s, s, 1)) of the file's texels (to 8-bit rounding)."""
    activate()
    from PIL import Image

    images = _write_card_images(tmp_path)
    _gltf_card(tmp_path, images, normal_scale=0.4)
    (tmp_path / "shot.yaml").write_text("timeline: {fps: 24, first: 0, last: 1}\ncamera: {position: [0, 1, 9], look_at: [0, 0, 0]}\nimports:\n  - {file: card.glb}\n")
    from motion.pipeline.scene import load_scene

    (mat,) = load_scene(tmp_path / "shot.yaml").scene.materials
    ours = np.asarray(Image.open(mat.normal_map.file).convert("RGB"), dtype=np.float64) / 255 * 2 - 1
    n = np.asarray(Image.open(tmp_path / "ripple.png").convert("RGB"), dtype=np.float64) / 255 * 2 - 1
    n[:, :, :2] *= 0.4
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    assert mat.normal_map.raw
    np.testing.assert_allclose(ours, n, atol=2.5 / 255)


@pytest.mark.parametrize("mode, factor", [("MASK", 0.6), ("BLEND", 0.6), ("OPAQUE", 0.6)])
def test_gltf_alpha_modes_become_opacity(tmp_path: Path, mode: str, factor: float) -> None:
    """alphaMode: MASK cuts alpha x factor at alphaCutoff (0.5) into 0/1, BLEND keeps
    alpha x factor as coverage, OPAQUE ignores alpha."""
    activate()
    from PIL import Image

    from motion.pipeline.scene import load_scene

    images = _write_card_images(tmp_path)
    _gltf_card(tmp_path, images, alpha_mode=mode, alpha=factor)
    (tmp_path / "shot.yaml").write_text("timeline: {fps: 24, first: 0, last: 1}\ncamera: {position: [0, 1, 9], look_at: [0, 0, 0]}\nimports:\n  - {file: card.glb}\n")
    (mat,) = load_scene(tmp_path / "shot.yaml").scene.materials
    alpha = np.asarray(Image.open(tmp_path / "colour_a.png").convert("RGBA"), dtype=np.float64)[:, :, 3] / 255
    if mode == "OPAQUE":
        assert mat.opacity == 1.0
        return
    assert mat.opacity.raw
    ours = np.asarray(Image.open(mat.opacity.file), dtype=np.float64) / 255
    expect = (alpha * factor >= 0.5).astype(float) if mode == "MASK" else alpha * factor
    np.testing.assert_allclose(ours, expect, atol=0.5 / 255 + 1e-9)


@pytest.mark.parametrize("line", ["vt nan 0", "vn 0 1e39 0"])
def test_render_mesh_refuses_non_finite_attributes(tmp_path: Path, line: str) -> None:
    """A texture coordinate or normal that float32 cannot hold is an AssetError naming the
    file, not NaN pixels in a worker."""
    from motion.pipeline.errors import AssetError
    from motion.pipeline.meshes import load_render_mesh

    path = tmp_path / "bad.obj"
    vt = line if line.startswith("vt") else "vt 1 0"
    vn = line if line.startswith("vn") else "vn 0 0 1"
    path.write_text(f"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\n{vt}\nvn 0 0 1\n{vn}\nf 1/1/1 2/2/2 3/1/1\n")
    with pytest.raises(AssetError, match=r"bad\.obj: (texture coordinate|normal) of render vertex 1 is not finite"):
        load_render_mesh(path)


def test_bad_attributes_of_a_deforming_mesh_fail_validation(tmp_path: Path) -> None:
    """The render vertices of a deforming mesh are read at validation, so a texture
    coordinate float32 cannot hold is a located error before any task."""
    from motion.pipeline.errors import SceneError

    _write_ball(tmp_path)
    (tmp_path / "ball.obj").write_text((tmp_path / "ball.obj").read_text().replace("vt 0.000000 1.000000", "vt nan 1", 1))
    with pytest.raises(SceneError, match=r"objects\[1\]\.file: mesh file ball\.obj: texture coordinate of render vertex \d+ is not finite"):
        load(tmp_path, light_scene_yaml("  - {type: constant, radiance: 0.3}", _ball_yaml("grey"), resolution=RES, spp=SPP).replace("materials:\n", "materials:\n" + MATERIALS))
