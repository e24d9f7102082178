"""USD imports: stages authored here with usd-core; our evaluated world transforms,
vertex animation and camera field of view are compared with what USD itself computes
(ComputeLocalToWorldTransform, attribute interpolation) at frame and sub-frame times."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pxr = pytest.importorskip("pxr", reason="usd-core is not installed")
from pxr import Gf, Usd, UsdGeom, UsdLux, UsdShade, Sdf  # noqa: E402

from motion.pipeline.errors import SceneError  # noqa: E402
from motion.pipeline.motion.evaluate import evaluate  # noqa: E402
from motion.pipeline.scene.loader import load_scene  # noqa: E402

TCPS = 48.0  # time codes per second: not the scene's fps, to test the mapping
FPS = 24
CODES = [0.0, 3.0, 7.5, 12.0, 12.25, 20.0, 29.9, 36.0, 40.0]  # frames, sub-frames, keys, after


def author(path: Path) -> None:
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetTimeCodesPerSecond(TCPS)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(36)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    world = UsdGeom.Xform.Define(stage, "/World")
    world.AddTranslateOp().Set(Gf.Vec3d(0.5, 0, -1))
    world.AddRotateYOp().Set(25.0)
    arm = UsdGeom.Xform.Define(stage, "/World/Arm")
    t = arm.AddTranslateOp()
    o = arm.AddOrientOp()
    s = arm.AddScaleOp()
    for code, pos, quat, scale in ((0, (0, 1, 0), Gf.Quatf(1, 0, 0, 0), 1.0), (12, (1, 1.5, 0.2), Gf.Quatf(math.cos(0.6), math.sin(0.6) * 0.6, math.sin(0.6) * 0.8, 0), 1.5), (36, (0, 0.5, 2), Gf.Quatf(math.cos(1.2), 0, 0, math.sin(1.2)), 0.8)):
        t.Set(Gf.Vec3d(*pos), code)
        o.Set(quat, code)
        s.Set(Gf.Vec3f(scale, scale, scale), code)
    hand = UsdGeom.Xform.Define(stage, "/World/Arm/Hand")
    hand.AddTranslateOp().Set(Gf.Vec3d(0, 0.8, 0))
    r = hand.AddRotateZOp()
    r.Set(0.0, 0)
    r.Set(120.0, 24)
    mesh = UsdGeom.Mesh.Define(stage, "/World/Arm/Hand/Blob")
    mesh.GetFaceVertexCountsAttr().Set([4, 3])
    mesh.GetFaceVertexIndicesAttr().Set([0, 1, 2, 3, 0, 2, 4])
    base = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], float)
    for code, k in ((0, 0.0), (10, 1.0), (30, -0.5)):
        mesh.GetPointsAttr().Set([Gf.Vec3f(*(p + k * np.array([0, 0, p[0]]))) for p in base], code)
    mat = UsdShade.Material.Define(stage, "/World/Looks/Red")
    shader = UsdShade.Shader.Define(stage, "/World/Looks/Red/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.7, 0.1, 0.05))
    shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.2)
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.4)
    mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(mat)
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(0, 1, 6))
    cam.GetHorizontalApertureAttr().Set(36.0)
    cam.GetFocalLengthAttr().Set(35.0, 0)
    cam.GetFocalLengthAttr().Set(70.0, 24)
    cam.GetClippingRangeAttr().Set(Gf.Vec2f(0.1, 500))
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.AddRotateXOp().Set(-45.0)
    sun.GetIntensityAttr().Set(3.0)
    UsdLux.SphereLight.Define(stage, "/World/Bulb").GetIntensityAttr().Set(5.0)
    rect = UsdLux.RectLight.Define(stage, "/World/Panel")
    rect.GetWidthAttr().Set(2.0)
    rect.GetHeightAttr().Set(1.0)
    UsdLux.DomeLight.Define(stage, "/World/Sky").GetIntensityAttr().Set(0.25)
    stage.GetRootLayer().Save()


@pytest.fixture(scope="module")
def stage_file(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("usd")
    author(tmp / "layout.usda")
    (tmp / "shot.yaml").write_text(
        f"""timeline: {{fps: {FPS}, first: 0, last: 18}}
imports:
  - {{file: layout.usda, camera: Cam}}
render: {{resolution: [32, 24], spp: 2}}
"""
    )
    return tmp


def test_world_transforms_points_and_camera_match_usd(stage_file):
    loaded = load_scene(stage_file / "shot.yaml")
    stage = Usd.Stage.Open(str(stage_file / "layout.usda"))
    times = np.array(CODES) / TCPS
    motion = evaluate(loaded, times)
    for name, path in (("World", "/World"), ("Arm", "/World/Arm"), ("Hand", "/World/Arm/Hand"), ("Blob", "/World/Arm/Hand/Blob")):
        ours = motion.objects[name].matrices()
        xf = UsdGeom.Xformable(stage.GetPrimAtPath(path))
        for i, code in enumerate(CODES):
            theirs = np.array(xf.ComputeLocalToWorldTransform(Usd.TimeCode(code))).T
            np.testing.assert_allclose(ours[i], theirs, atol=1e-5, err_msg=f"{path} at time code {code}")
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Arm/Hand/Blob")).GetPointsAttr()
    for i, code in enumerate(CODES):
        np.testing.assert_allclose(motion.vertices["Blob"][i], np.array(points.Get(Usd.TimeCode(code)), float), atol=1e-5, err_msg=f"points at {code}")
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam"))
    for i, code in enumerate(CODES):
        focal = cam.GetFocalLengthAttr().Get(Usd.TimeCode(code))
        # exact at USD's samples; between them fov is keyed 16 times per interval (catmull-rom) (docs/imports.md)
        tol = 1e-5 if code in (0.0, 24.0) or code > 24 else 1e-2
        assert motion.camera_scalars["fov"][i] == pytest.approx(math.degrees(2 * math.atan(36.0 / (2 * focal))), abs=tol)
        theirs = np.array(cam.ComputeLocalToWorldTransform(Usd.TimeCode(code))).T
        np.testing.assert_allclose(motion.camera.matrices()[i], theirs @ np.diag([-1.0, 1, -1, 1]), atol=1e-5)


def test_materials_and_lights(stage_file):
    scene = load_scene(stage_file / "shot.yaml").scene
    red = next(m for m in scene.materials if m.name == "Red")
    assert red.type == "principled" and red.color == pytest.approx((0.7, 0.1, 0.05)) and red.metallic == pytest.approx(0.2) and red.roughness == pytest.approx(0.4)
    assert next(o for o in scene.objects if o.name == "Blob").material == "Red"
    kinds = {light.name: light.type for light in scene.lights}
    assert kinds == {"Sun.light": "directional", "Bulb.light": "point", "Sky.light": "constant"}
    panel = next(o for o in scene.objects if o.name == "Panel.light")
    assert panel.shape == "rectangle" and panel.width == 2.0 and panel.emission.radiance == pytest.approx((1.0, 1.0, 1.0))
    assert scene.camera.near == pytest.approx(0.1) and scene.camera.far == pytest.approx(500)


def test_bad_usd_files_are_located(tmp_path):
    (tmp_path / "broken.usda").write_text("#usda 1.0\ndef Xform \"A\" {\n  double3 xformOp:translate = (1, 2\n}\n")
    (tmp_path / "shot.yaml").write_text("camera: {position: [0, 0, 5], look_at: [0, 0, 0]}\nimports: [{file: broken.usda}]\n")
    with pytest.raises(SceneError) as err:
        load_scene(tmp_path / "shot.yaml")
    assert "\n" not in str(err.value) and "broken.usda: <stage>: cannot open the USD stage" in str(err.value)
    stage = Usd.Stage.CreateNew(str(tmp_path / "bad.usda"))
    mesh = UsdGeom.Mesh.Define(stage, "/Bad")
    mesh.GetPointsAttr().Set([Gf.Vec3f(0, 0, 0), Gf.Vec3f(1, 0, 0), Gf.Vec3f(0, 1, 0)])
    mesh.GetFaceVertexCountsAttr().Set([3])
    mesh.GetFaceVertexIndicesAttr().Set([0, 1, 7])
    stage.GetRootLayer().Save()
    (tmp_path / "shot.yaml").write_text("camera: {position: [0, 0, 5], look_at: [0, 0, 0]}\nimports: [{file: bad.usda}]\n")
    with pytest.raises(SceneError, match=r"bad\.usda: /Bad\.faceVertexIndices: index 7 is out of range for 3 points"):
        load_scene(tmp_path / "shot.yaml")


@pytest.mark.render
def test_textured_usd_card_renders_the_right_way_up(tmp_path):
    """primvars:st (faceVarying, t up as USD has it) and a UsdUVTexture on diffuseColor:
    a card whose image is red above and blue below renders red at the top."""
    from PIL import Image

    from _support import assert_card_upright

    img = np.zeros((8, 8, 3), np.uint8)
    img[:4], img[4:] = (255, 0, 0), (0, 0, 255)
    Image.fromarray(img).save(tmp_path / "card.png")
    stage = Usd.Stage.CreateNew(str(tmp_path / "card.usda"))
    mesh = UsdGeom.Mesh.Define(stage, "/Card")
    mesh.GetPointsAttr().Set([Gf.Vec3f(-1, -1, 0), Gf.Vec3f(1, -1, 0), Gf.Vec3f(1, 1, 0), Gf.Vec3f(-1, 1, 0)])
    mesh.GetFaceVertexCountsAttr().Set([4])
    mesh.GetFaceVertexIndicesAttr().Set([0, 1, 2, 3])
    st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
    st.Set([Gf.Vec2f(0, 0), Gf.Vec2f(1, 0), Gf.Vec2f(1, 1), Gf.Vec2f(0, 1)])
    mat = UsdShade.Material.Define(stage, "/Looks/Card")
    surface = UsdShade.Shader.Define(stage, "/Looks/Card/Surface")
    surface.CreateIdAttr("UsdPreviewSurface")
    tex = UsdShade.Shader.Define(stage, "/Looks/Card/Image")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("card.png")
    surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3))
    mat.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(mat)
    stage.GetRootLayer().Save()
    assert_card_upright(tmp_path, "card.usda")


def _units_stage(path: Path, units: float | None, up: Any) -> None:
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetTimeCodesPerSecond(24.0)
    if units is not None:
        UsdGeom.SetStageMetersPerUnit(stage, units)
    UsdGeom.SetStageUpAxis(stage, up)
    UsdGeom.Xform.Define(stage, "/Box").AddTranslateOp().Set(Gf.Vec3d(100, 0, 50))
    wheel = UsdGeom.Xform.Define(stage, "/Wheel")
    spin = wheel.AddRotateXOp()
    for code, angle in ((0, 0.0), (24, 270.0), (48, 720.0)):
        spin.Set(angle, code)
    stage.GetRootLayer().Save()


@pytest.mark.parametrize("override, expect", [("", [1.0, 0.5, 0.0]), (", units: 1, up_axis: y", [100.0, 0.0, 50.0])])
def test_usd_units_and_up_axis_apply_on_import(tmp_path, override, expect):
    """A centimetre, Z-up stage: an Xform at (100, 0, 50) cm lands at (1, 0.5, 0) m in our
    +Y-up metres; the import entry's `units:` / `up_axis:` override the stage's."""
    _units_stage(tmp_path / "cm.usda", 0.01, UsdGeom.Tokens.z)
    (tmp_path / "shot.yaml").write_text(f"timeline: {{fps: 24, first: 0, last: 2}}\ncamera: {{position: [0, 1, 9], look_at: [0, 0, 0]}}\nimports:\n  - {{file: cm.usda{override}}}\n")
    motion = evaluate(load_scene(tmp_path / "shot.yaml"), np.zeros(1))
    np.testing.assert_allclose(motion.objects["Box"].matrices()[0][:3, 3], expect, atol=1e-9)


def test_usd_rotate_op_turns_by_its_angle_not_the_shortest_arc(tmp_path):
    """rotateX keyed 0 -> 270 -> 720 degrees turns the long way, as USD interpolates the
    angle: at every sub-frame our world matrix is USD's own (135 degrees at code 12, not -45)."""
    _units_stage(tmp_path / "spin.usda", None, UsdGeom.Tokens.y)
    (tmp_path / "shot.yaml").write_text("timeline: {fps: 24, first: 0, last: 48}\ncamera: {position: [0, 1, 9], look_at: [0, 0, 0]}\nimports:\n  - {file: spin.usda}\n")
    codes = np.array([0, 3, 6, 12, 17.5, 24, 30, 36, 41, 47.5])
    motion = evaluate(load_scene(tmp_path / "shot.yaml"), codes / 24.0)
    stage = Usd.Stage.Open(str(tmp_path / "spin.usda"))
    xf = UsdGeom.Xformable(stage.GetPrimAtPath("/Wheel"))
    for i, code in enumerate(codes):
        theirs = np.array(xf.ComputeLocalToWorldTransform(Usd.TimeCode(float(code)))).T
        np.testing.assert_allclose(motion.objects["Wheel"].matrices()[i], theirs, atol=1e-6, err_msg=f"time code {code}")


def _sublayered_shot(folder: Path) -> None:
    """shot.yaml importing shot.usda, whose one sublayer set.usda places /World/Box at x = 1."""
    sub = Usd.Stage.CreateNew(str(folder / "set.usda"))
    UsdGeom.Xform.Define(sub, "/World/Box").AddTranslateOp().Set(Gf.Vec3d(1, 0, 0))
    sub.GetRootLayer().Save()
    root = Sdf.Layer.CreateNew(str(folder / "shot.usda"))
    root.subLayerPaths.append("set.usda")
    root.Save()
    (folder / "shot.yaml").write_text("camera: {position: [0, 0, 5], look_at: [0, 0, 0]}\nimports: [{file: shot.usda}]\n")


def test_a_kept_usd_import_is_read_without_usd_core_until_a_layer_changes(tmp_path, monkeypatch):
    """The second load of a USD import reads its kept records (imports/memo.py) and never
    imports usd-core (0.3 s of each `motion validate`, and of each worker); a change to a
    sublayer, not the root layer the key names, is seen and the stage read again."""
    import subprocess
    import sys

    _sublayered_shot(tmp_path)
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))

    def box_x() -> tuple[float, bool]:
        code = ("import sys\nfrom motion.pipeline.scene.loader import load_scene\n"
                f"scene = load_scene({str(tmp_path / 'shot.yaml')!r}).scene\n"
                "print(next(o for o in scene.objects if o.name == 'Box').transform.translate[0], 'pxr' in sys.modules)\n")
        res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
        assert res.returncode == 0, res.stderr
        x, read = res.stdout.split()
        return float(x), read == "True"

    assert box_x() == (1.0, True)
    assert box_x() == (1.0, False)  # kept
    sub = Usd.Stage.Open(str(tmp_path / "set.usda"))
    UsdGeom.Xformable(sub.GetPrimAtPath("/World/Box")).GetOrderedXformOps()[0].Set(Gf.Vec3d(2, 0, 0))
    sub.GetRootLayer().Save()
    assert box_x() == (2.0, True)
    assert box_x() == (2.0, False)


def test_a_kept_usd_import_is_not_used_when_a_layer_became_a_link_outside(tmp_path, monkeypatch):
    """A sublayer replaced by a link to the same bytes outside the scene's folder: the kept
    records are not used (the file the reader read is no longer at its place), and the
    reader's layer check refuses the stage as it would have the first time."""
    import shutil

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    shot = tmp_path / "shot"
    shot.mkdir()
    _sublayered_shot(shot)
    load_scene(shot / "shot.yaml")
    (tmp_path / "elsewhere").mkdir()
    shutil.move(str(shot / "set.usda"), str(tmp_path / "elsewhere" / "set.usda"))
    (shot / "set.usda").symlink_to(tmp_path / "elsewhere" / "set.usda")
    with pytest.raises(SceneError, match="outside the scene's folder"):
        load_scene(shot / "shot.yaml")


def test_a_non_uniform_scale_above_a_turning_child_is_usds_own_matrix(tmp_path):
    """/Stretch scales (1, 2, 1) and slides; under it /Stretch/Spin turns about X on keys
    and about Y, with a non-uniform scale of its own, and /Stretch/Spin/Tip sits off its
    origin: at every sub-frame our world matrices are USD's ComputeLocalToWorldTransform
    (a per-axis product of scales missed by 0.34 m at the first time checked)."""
    stage = Usd.Stage.CreateNew(str(tmp_path / "stretch.usda"))
    stage.SetTimeCodesPerSecond(24.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    top = UsdGeom.Xform.Define(stage, "/Stretch")
    move = top.AddTranslateOp()
    move.Set(Gf.Vec3d(0, 0, 0), 0)
    move.Set(Gf.Vec3d(0, 2.52, 0), 30)
    top.AddScaleOp().Set(Gf.Vec3f(1, 2, 1))
    spin = UsdGeom.Xform.Define(stage, "/Stretch/Spin")
    turn = spin.AddRotateXOp()
    turn.Set(0.0, 0)
    turn.Set(180.0, 48)
    spin.AddRotateYOp().Set(25.0)
    spin.AddScaleOp().Set(Gf.Vec3f(0.3, 0.5, 0.8))
    UsdGeom.Xform.Define(stage, "/Stretch/Spin/Tip").AddTranslateOp().Set(Gf.Vec3d(0, 1, 0.5))
    stage.GetRootLayer().Save()
    (tmp_path / "shot.yaml").write_text("timeline: {fps: 24, first: 0, last: 48}\ncamera: {position: [0, 1, 9], look_at: [0, 0, 0]}\nimports:\n  - {file: stretch.usda}\n")
    codes = np.array([0, 7.5, 12, 24, 30.25, 45, 48])
    motion = evaluate(load_scene(tmp_path / "shot.yaml"), codes / 24.0)
    for name, path in (("Spin", "/Stretch/Spin"), ("Tip", "/Stretch/Spin/Tip")):
        xf = UsdGeom.Xformable(stage.GetPrimAtPath(path))
        for i, code in enumerate(codes):
            theirs = np.array(xf.ComputeLocalToWorldTransform(Usd.TimeCode(float(code)))).T
            np.testing.assert_allclose(motion.objects[name].matrices()[i], theirs, atol=1e-5, err_msg=f"{path} at time code {code}")
