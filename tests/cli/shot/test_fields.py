"""Field rendering (`motion render --fields 60i`, shot/fields.py): every field
is rendered at its own instant with its own shutter and only its own rows, then woven into
interlaced frames (EXR with the field order and times, an interlaced movie)."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pytest
import yaml

from _support import run_motion
from motion.pipeline.frame_output import read_frame
from motion.pipeline.telecine.cadence import parse_cadence, plan
from motion.pipeline.field_model import parity_of
from motion.pipeline.telecine.interlace import field_range

SPEED = 3.0  # m/s downwards
Y0 = 0.45  # m, the bar's centre at t = 0 (0.3 m tall)
PX_PER_M = 32.0  # 64 px across an orthographic width of 2 m
AV_FIELD_TT = 2


def bar_scene(folder: Path) -> Path:
    """A bright horizontal bar 0.3 m tall falling at 3 m/s in front of an orthographic
    camera (64 x 48 px, 1.5 m tall), a 10-degree shutter so its edges stay sharp."""
    doc = {
        "name": "bar",
        "timeline": {"fps": 24, "first": 0, "last": 3},
        "camera": {"type": "orthographic", "position": [0, 0, 5], "look_at": [0, 0, 0], "ortho_width": 2.0, "shutter": {"angle": 10}},
        "lights": [],
        "materials": [{"name": "glow", "type": "diffuse", "color": 0}],
        "objects": [{
            "name": "bar", "shape": "cube", "size": [3.0, 0.3, 0.1], "material": "glow", "emission": {"radiance": 1.0},
            "motion": {"type": "keyframes", "time_unit": "seconds", "extrapolation": "linear", "channels": {
                "translate": {"keys": [{"time": 0.0, "value": [0, Y0, 0]}, {"time": 1.0, "value": [0, Y0 - SPEED, 0]}]}}},
        }],
        "render": {"resolution": [64, 48], "spp": 16, "max_depth": 2},
    }
    path = folder / "bar.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("fields")
    out = folder / "out"
    proc = run_motion("render", str(bar_scene(folder)), "--fields", "60i", "--frames", "0-1", "-o", str(out), "--workers", "1")
    assert proc.returncode == 0, proc.stderr
    return out


def centre_row(rows: np.ndarray, parity: int) -> float:
    """Intensity-weighted centre of the bar (frame rows) from a field's column: field row r
    is frame row 2 r + parity, its centre at 2 r + parity + 0.5."""
    y = 2 * np.arange(len(rows)) + parity + 0.5
    return float((rows * y).sum() / rows.sum())


def expected_centre(t: float, parity: int) -> float:
    """The same centre computed from the exact coverage of the field's own pixel rows by the
    bar at time t (image row 0 is at y = +0.75 m; the bar spans its centre +- 0.15 m)."""
    centre = (0.75 - (Y0 - SPEED * t)) * PX_PER_M
    top, bottom = centre - 0.15 * PX_PER_M, centre + 0.15 * PX_PER_M
    y = 2 * np.arange(24) + parity
    coverage = np.clip(np.minimum(y + 1, bottom) - np.maximum(y, top), 0.0, 1.0)
    return centre_row(coverage, parity)


def test_each_field_shows_the_bar_at_its_own_time(rendered: Path) -> None:
    times = []
    for f in range(4):
        field = read_frame(rendered / "fields" / f"bar.{f:04d}.exr")
        meta = field.meta
        assert field.rgba.shape == (24, 64, 4)  # only its own rows were rendered
        assert meta["field"] == parity_of(f, "tff") and meta["fieldOrder"] == "tff"
        t = float(meta["time"])
        assert t == pytest.approx(f * 1001 / 60000, abs=1e-6)
        # its own shutter: 10 degrees of a field (1/59.94 s), centred on its instant
        assert meta["shutter_close"] - meta["shutter_open"] == pytest.approx(10 / 360 * 1001 / 60000, rel=1e-6)
        column = field.rgba[:, 20:44, 0].mean(axis=1)
        assert centre_row(column, f % 2) == pytest.approx(expected_centre(t, f % 2), abs=0.2)
        times.append(t)
    assert len(set(times)) == 4


def test_fields_weave_into_interlaced_frames_with_four_instants(rendered: Path) -> None:
    seen = []
    for k in range(2):
        frame = read_frame(rendered / f"bar.{k:04d}.exr")
        meta = frame.meta
        assert frame.rgba.shape == (48, 64, 4)
        assert frame.header["framesPerSecond"] == Fraction(30000, 1001)
        assert meta["fieldOrder"] == "tff" and meta["firstFieldSource"] == 2 * k
        for parity, t in ((0, meta["firstFieldTime"]), (1, meta["secondFieldTime"])):
            column = frame.rgba[parity::2, 20:44, 0].mean(axis=1)
            assert centre_row(column, parity) == pytest.approx(expected_centre(t, parity), abs=0.2)
            seen.append(t)
    # four fields, four instants 1/59.94 s apart: the bar moved 1.6 rows between fields
    assert np.allclose(np.diff(seen), 1001 / 60000, atol=1e-6)
    # a 3:2 pulldown of 24p shows at most two film times in any frame, three in two frames
    pulldown = plan(8, parse_cadence("3:2"), "tff")
    assert max(len({vf.top, vf.bottom}) for vf in pulldown) == 2
    assert max(len({a.top, a.bottom, b.top, b.bottom}) for a, b in zip(pulldown, pulldown[1:])) <= 3


def test_the_movie_is_flagged_interlaced(rendered: Path) -> None:
    with av.open(str(rendered / "bar_60i.mov")) as container:
        stream = container.streams.video[0]
        frames = list(container.decode(stream))
        assert stream.codec_context.field_order == AV_FIELD_TT
        assert stream.average_rate == Fraction(30000, 1001)
    assert len(frames) == 2 and all(f.interlaced_frame for f in frames)


def test_field_range_covers_the_shot_in_whole_frames() -> None:
    assert field_range(Fraction(24), 0, 23, Fraction(60000, 1001)) == (0, 59)
    f0, f1 = field_range(Fraction(24), 10, 13, Fraction(60000, 1001))
    assert f0 % 2 == 0 and f1 % 2 == 1
    assert f0 * 1001 / 60000 <= 10 / 24 and (f1 + 1) * 1001 / 60000 >= 14 / 24
    assert field_range(Fraction(25), 0, 24, Fraction(50)) == (0, 49)


def test_fields_refuse_an_odd_height_and_shards(tmp_path: Path) -> None:
    scene = bar_scene(tmp_path)
    proc = run_motion("render", str(scene), "--fields", "60i", "--resolution", "64x47", "-o", str(tmp_path / "o"))
    assert proc.returncode == 2 and "odd" in proc.stderr and "Traceback" not in proc.stderr
    proc = run_motion("render", str(scene), "--fields", "60i", "--shard", "1/2", "-o", str(tmp_path / "o"))
    assert proc.returncode == 2 and "--shard" in proc.stderr
