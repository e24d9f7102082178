"""`--check` knows the complete frames without baking the shot again when every frame's
header says it was made from this version, and `--check --deliver` decodes each frame once
(issue 38, item 5): a frame made from another version is still found stale, naming what
changed, and a frame cut short is still found incomplete."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from farm_util import TINY, motion
from tests.cli.shot.test_reruns import SHOT


def _write(path: Path, doc: dict) -> Path:
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _check(scene: Path, out: Path, monkeypatch: pytest.MonkeyPatch, *deliver: str) -> tuple[list[int], Exception | None]:
    """`motion render --check` in this process; how many bakes it ran and its error."""
    from motion.pipeline.shot import render as render_mod
    from motion.pipeline.shot.request import RenderRequest

    bakes: list[int] = []
    real = render_mod.motion_inputs

    def counted(*args, **kwargs):  # the real bake, counted
        bakes.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(render_mod, "motion_inputs", counted)
    req = RenderRequest(scene=scene, output_dir=out, render_overrides={"resolution": (16, 12), "spp": 1}, check=True, progress=False,
                        deliver=deliver[0] if deliver else None)
    try:
        render_mod.run_render(req)
    except Exception as exc:  # IncompleteJobError: a stale frame
        return bakes, exc
    return bakes, None


def test_check_bakes_nothing_for_frames_of_this_version_and_names_another_versions(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Frames rendered from this scene: --check bakes nothing (before: the whole shot was
    simulated and baked again to compare each frame's motion). After a key moves, their
    headers name another version: the check bakes, and names frames 4-7 and why. (A cache
    root of its own: another test's render of the same edited shot keeps its identities,
    and a check that finds them kept rightly bakes nothing.)"""
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    out = tmp_path / "out"
    scene = _write(tmp_path / "keys.yaml", SHOT)
    assert motion("render", scene, "-o", out, *TINY).returncode == 0
    bakes, err = _check(scene, out, monkeypatch)
    assert err is None and bakes == []
    doc = json.loads(json.dumps(SHOT))
    doc["objects"][1]["motion"]["channels"]["translate"]["keys"][2]["value"] = [1.5, 0.6, 0]
    _write(scene, doc)
    bakes, err = _check(scene, out, monkeypatch)
    assert bakes == [1] and err is not None
    assert "4-7 were made from other motion (motion of box changed)" in str(err) and "0-3" not in str(err)


def test_check_deliver_finds_a_frame_cut_short_without_decoding_it_whole(tmp_path: Path) -> None:
    """`--check --deliver` reads headers and chunk tables (the deliverable decodes each
    frame once): a frame cut short by one byte or by half is still not complete (exit 3,
    named), and no deliverable is made."""
    out = tmp_path / "out"
    scene = _write(tmp_path / "keys.yaml", SHOT)
    assert motion("render", scene, "-o", out, *TINY).returncode == 0
    frame = sorted(out.glob("keys.*.exr"))[5]
    whole = frame.read_bytes()
    for cut in (1, len(whole) // 2):
        frame.write_bytes(whole[:-cut])
        res = motion("render", scene, "-o", out, *TINY, "--check", "--deliver", "24p")
        assert res.returncode == 3, res.stderr
        assert "not complete: 5 do not read back" in res.stderr
        assert not (out / "deliver").exists()
    frame.write_bytes(whole)
    res = motion("render", scene, "-o", out, *TINY, "--check", "--deliver", "24p")
    assert res.returncode == 0, res.stderr
    assert len(list((out / "deliver").glob("keys_24p_v001.mov"))) == 1


def test_reads_whole_decodes_no_more_than_the_last_chunk(tmp_path: Path) -> None:
    """reads_whole: a whole frame is; the same bytes cut anywhere from one byte to all but
    the header are not."""
    from motion.pipeline.identity.record import reads_whole

    out = tmp_path / "out"
    scene = _write(tmp_path / "keys.yaml", SHOT)
    assert motion("render", scene, "-o", out, *TINY, "--frames", "0").returncode == 0
    frame = next(out.glob("keys.*.exr"))
    whole = frame.read_bytes()
    assert reads_whole(frame)
    cut = tmp_path / "cut.exr"
    for keep in (len(whole) - 1, len(whole) - 100, len(whole) * 3 // 4, len(whole) // 2, 400):
        cut.write_bytes(whole[:keep])
        assert not reads_whole(cut), keep
    assert not reads_whole(tmp_path / "absent.exr")


def test_check_without_deliver_writes_nothing(tmp_path: Path) -> None:
    """A scene that declares `output.deliver`: `render --check` built those deliverables
    (a contact sheet v001 and the manifest written into the folder it checked). A check
    writes nothing without `--deliver`: the folder is byte for byte as it was, and the
    line says what was not made and how to ask; `--check --deliver contact` makes it."""
    out = tmp_path / "out"
    doc = json.loads(json.dumps(SHOT))
    doc.setdefault("output", {})["deliver"] = ["contact"]
    scene = _write(tmp_path / "keys.yaml", doc)
    assert motion("render", scene, "-o", out, *TINY, "--deliver", "none").returncode == 0
    before = {str(p.relative_to(out)): (p.stat().st_mtime_ns, p.read_bytes() if p.is_file() else None) for p in out.rglob("*")}
    res = motion("render", scene, "-o", out, *TINY, "--check")
    assert res.returncode == 0, res.stderr
    assert {str(p.relative_to(out)): (p.stat().st_mtime_ns, p.read_bytes() if p.is_file() else None) for p in out.rglob("*")} == before
    assert "contact: not made: --check makes no deliverables unless asked: --check --deliver" in res.stderr, res.stderr
    res = motion("render", scene, "-o", out, *TINY, "--check", "--deliver", "contact")
    assert res.returncode == 0, res.stderr
    assert (out / "deliver" / "keys_contact_v001.png").is_file()
