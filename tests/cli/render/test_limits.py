"""The render's sizing limits from the environment (pipeline/limits.py): a bad value or one
over its limit is one line before any work."""

from __future__ import annotations

from pathlib import Path

import pytest

from _scenes import BASE


@pytest.mark.parametrize("name", ["MOTION_MAX_LANES", "MOTION_ASSET_CACHE_CAP", "MOTION_VIEWED_MB"])
@pytest.mark.parametrize("value", ["abc", "0", "-5", "1e9"])
def test_bad_sizing_environment_variable_is_one_line_before_any_work(tmp_path: Path, name: str, value: str) -> None:
    from _support import run_motion

    (tmp_path / "scene.yaml").write_text(BASE)
    out = tmp_path / "out"
    res = run_motion("render", str(tmp_path / "scene.yaml"), "--preset", "ci-smoke", "-o", str(out), env={name: value}, timeout=120)
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr
    assert res.stderr.strip().splitlines()[-1] == f"error: ${name}: expected a positive whole number, got {value!r}"
    assert not list(out.glob("*.exr"))  # refused before any frame


def test_max_lanes_over_its_limit_is_refused_before_any_work(tmp_path: Path) -> None:
    # 2^40 lanes would ask one render pass for ~80 TB; the limit is 2^28 (~21 GB)
    from _support import run_motion

    (tmp_path / "scene.yaml").write_text(BASE)
    out = tmp_path / "out"
    big = str(1 << 40)
    res = run_motion("render", str(tmp_path / "scene.yaml"), "--preset", "ci-smoke", "-o", str(out), env={"MOTION_MAX_LANES": big}, timeout=120)
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr
    assert res.stderr.strip().splitlines()[-1] == f"error: $MOTION_MAX_LANES: {big} is over the limit of {1 << 28}"
    assert not list(out.glob("*.exr"))
