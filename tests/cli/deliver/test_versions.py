"""Deliverables a studio can cut with (issues 36, 37, 38): made from the whole shot whatever
frames a run rendered, versioned and never overwritten, a part of the shot only when asked
and named apart; formats as records; frame numbers carried, not parsed from file names; a
damaged manifest discarded with one warning; one reader of our EXR header attributes."""

from __future__ import annotations

import json
import os
import re
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pytest
import yaml

from farm_util import ROOT, SCENE, TINY, motion

pytestmark = pytest.mark.render


def _scene(tmp_path: Path, last: int = 11, **output: object) -> Path:
    """farm-tiny cut to frames 0-`last` (a shot of a dozen frames renders in about a second)."""
    doc = yaml.safe_load(SCENE.read_text())
    doc["timeline"]["last"] = last
    doc.setdefault("output", {}).update(output)
    path = tmp_path / "shot.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def _frames(movie: Path) -> int:
    with av.open(str(movie)) as c:
        return sum(1 for _ in c.decode(video=0))


def _manifest(out: Path) -> dict:
    return json.loads((out / "deliver" / "manifest.json").read_text())


def _recolour_floor(scene: Path, value: float) -> None:
    doc = yaml.safe_load(scene.read_text())
    next(m for m in doc["materials"] if m["name"] == "floor")["color"] = value
    scene.write_text(yaml.safe_dump(doc))


def test_a_partial_rerun_rebuilds_the_whole_shot_as_a_new_version(tmp_path: Path) -> None:
    """The shot, then `--overwrite --frames 4-7` with nothing changed: the same pixels, so
    no new version (before: v002, byte-identical to v001, "frames 4-7 changed since v001":
    the manifest hashed whole EXR files, whose headers change on every render). The floor
    recoloured and 4-7 rendered again: v002 of every format, holding all 12 frames, naming
    exactly the frames whose pixels changed; v001 untouched; the same command again makes
    no v003."""
    scene, out = _scene(tmp_path), tmp_path / "out"
    args = ["render", scene, "-o", out, *TINY, "--deliver", "24p,60i,contact"]
    first = motion(*args)
    assert first.returncode == 0, first.stderr
    deliver = out / "deliver"
    v1 = deliver / "farm-tiny_24p_v001.mov"
    v1_bytes = v1.read_bytes()
    assert _frames(v1) == 12
    same = motion(*args, "--overwrite", "--frames", "4-7")
    assert same.returncode == 0, same.stderr
    assert "4 rendered" in same.stderr
    assert same.stderr.count("up to date (v001, frames 0-11 unchanged") == 3 and "changed" not in same.stderr.replace("unchanged", ""), same.stderr
    assert not list(deliver.glob("*v002*"))
    _recolour_floor(scene, 0.2)
    fix = motion(*args, "--overwrite", "--frames", "4-7")
    assert fix.returncode == 0, fix.stderr
    v2 = deliver / "farm-tiny_24p_v002.mov"
    assert _frames(v2) == 12 and v1.read_bytes() == v1_bytes
    assert len(list((deliver / "60i_v002").glob("*.exr"))) == 15 and len(list((deliver / "60i_v001").glob("*.exr"))) == 15
    assert (deliver / "farm-tiny_contact_v001.png").is_file() and (deliver / "farm-tiny_contact_v002.png").is_file()
    assert fix.stderr.count("(frames 4-7 changed since v001)") == 3, fix.stderr  # the 24p and 60i movies, the sheet
    made = _manifest(out)["deliverables"]
    assert set(made) == {"24p", "60i", "contact"} and all(e["latest"] == "v002" for e in made.values())
    versions = made["24p"]["versions"]
    assert [v["frames"] for v in versions.values()] == ["0-11", "0-11"]
    files = versions["v002"]["frame_files"]
    assert sorted(map(int, files)) == list(range(12)) and files["5"]["name"] == "farm-tiny.0005.exr"
    changed = sorted(int(n) for n in files if files[n]["pixels"] != versions["v001"]["frame_files"][n]["pixels"])
    assert changed == [4, 5, 6, 7]
    again = motion(*args, "--frames", "4-7")
    assert again.returncode == 0, again.stderr
    assert again.stderr.count("up to date (v002") == 3, again.stderr
    assert not list(deliver.glob("*v003*"))


def test_a_deliverable_of_part_of_the_shot_is_asked_for_and_named_apart(tmp_path: Path) -> None:
    """`--frames 0-3 --deliver 24p` of a 12-frame shot is refused before the first frame,
    naming what the shot lacks and the way to a part; `--deliver-frames 0-3` makes one,
    named apart from the shot's. The scene's own output.deliver leaves the movie out and
    says why, and makes the contact sheet of the frames there are, naming those it lacks."""
    scene, out = _scene(tmp_path), tmp_path / "out"
    refused = motion("render", scene, "-o", out, *TINY, "--frames", "0-3", "--deliver", "24p")
    assert refused.returncode == 2 and "Traceback" not in refused.stderr
    assert "the shot (frames 0-11) lacks frames 4-11" in refused.stderr and "--deliver-frames 0-3" in refused.stderr
    assert not out.exists() or not list(out.glob("*.exr"))
    part = motion("render", scene, "-o", out, *TINY, "--frames", "0-3", "--deliver", "24p", "--deliver-frames", "0-3")
    assert part.returncode == 0, part.stderr
    assert _frames(out / "deliver" / "farm-tiny_24p_0-3_v001.mov") == 4
    assert _manifest(out)["deliverables"]["24p@0-3"]["part"] == "0-3"
    (tmp_path / "d").mkdir()
    declared = _scene(tmp_path / "d", deliver=["24p", "contact"])
    res = motion("render", declared, "-o", tmp_path / "d" / "out", *TINY, "--frames", "0-3")
    assert res.returncode == 0, res.stderr
    assert "24p: not made: the shot (frames 0-11) lacks frames 4-11" in res.stderr
    assert (tmp_path / "d" / "out" / "deliver" / "farm-tiny_contact_v001.png").is_file()
    assert "(lacks frames 4-11)" in res.stderr


def test_frame_numbers_travel_with_the_paths(tmp_path: Path) -> None:
    """`output.filename: "{name}_####.exr"` (which validates): every frame rendered, then
    `--deliver` ended in a ValueError traceback parsing numbers back from the names."""
    scene, out = _scene(tmp_path, last=3, filename="{name}_####.exr"), tmp_path / "out"
    res = motion("render", scene, "-o", out, *TINY, "--deliver", "24p,contact")
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stderr
    assert (out / "farm-tiny_0002.exr").is_file()
    assert _frames(out / "deliver" / "farm-tiny_24p_v001.mov") == 4
    assert _manifest(out)["deliverables"]["24p"]["versions"]["v001"]["frame_files"]["2"]["name"] == "farm-tiny_0002.exr"


def _damage(out: Path, how: str) -> None:
    path = out / "deliver" / "manifest.json"
    good = json.loads(path.read_text())
    path.unlink()
    if how == "fifo":
        os.mkfifo(path)
    elif how == "deep":
        path.write_text("[" * 100_000 + "]" * 100_000)
    elif how == "types":
        good["deliverables"]["24p"]["versions"]["v001"]["outputs"] = "farm-tiny_24p_v001.mov"
        path.write_text(json.dumps(good))
    elif how == "outside":  # an entry naming a file outside -o, of the size it records
        victim = out.parent / "victim.mov"
        victim.write_bytes(b"x" * 10)
        good["deliverables"]["24p"]["versions"]["v001"]["outputs"] = [{"name": "../../victim.mov", "size": 10}]
        path.write_text(json.dumps(good))


@pytest.mark.parametrize("how", ["fifo", "deep", "types", "outside"])
def test_a_damaged_manifest_is_discarded_with_one_warning(tmp_path: Path, how: str) -> None:
    """A manifest.json that is a FIFO (hung), nested 100,000 deep or of the wrong types
    (tracebacks), or whose entry names an output outside -o: one warning line, a new
    version made, nothing overwritten, exit 0."""
    scene, out = _scene(tmp_path, last=3), tmp_path / "out"
    args = ["render", scene, "-o", out, *TINY, "--deliver", "24p"]
    assert motion(*args).returncode == 0
    v1 = (out / "deliver" / "farm-tiny_24p_v001.mov").read_bytes()
    _damage(out, how)
    res = motion(*args)
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stderr
    assert res.stderr.count("manifest.json: damaged") == 1
    assert (out / "deliver" / "farm-tiny_24p_v001.mov").read_bytes() == v1
    assert (out / "deliver" / "farm-tiny_24p_v002.mov").is_file()
    assert _manifest(out)["deliverables"]["24p"]["latest"] == "v002"


def test_a_new_format_is_one_record(tmp_path: Path) -> None:
    """A format is one record in the registry: `review25` (H.264 at PAL speed) was added as
    one line and is made by the movie maker; the schema and `--deliver` take its name."""
    from motion.pipeline.deliverables import FORMATS
    from motion.pipeline.frame_output import write_frame
    from motion.pipeline.scene.schema import OutputSettings
    from motion.pipeline.telecine.deliver import deliver

    assert FORMATS["review25"].kind == "movie" and OutputSettings(deliver=["review25"]).deliver == ["review25"]
    frames = tmp_path / "frames"
    for i in range(3):
        write_frame(frames / f"s.{i:04d}.exr", np.full((12, 16, 4), 0.1 * (i + 1), np.float32), {"frame": i}, fps=Fraction(24))
    done = deliver(frames, tmp_path / "d", "review25")
    with av.open(str(done["review25"][0])) as c:
        assert c.streams.video[0].average_rate == 25 and c.streams.video[0].codec_context.name == "h264"


def test_only_frame_output_knows_the_header_prefix() -> None:
    """Our EXR attributes are read through frame_output (motion_meta / read_meta / Frame.meta):
    the `motion:` prefix was stripped by hand in four more modules."""
    offenders = [str(p.relative_to(ROOT)) for p in (ROOT / "pipeline").rglob("*.py")
                 if p.name != "frame_output.py" and re.search(r"""["']motion:["']""", p.read_text())]
    assert offenders == []


def test_no_format_name_is_written_outside_the_registry() -> None:
    """The deliverable formats are known by their records only: no `("60i", "50i")` tuples
    or format if-chains in the shot and telecine stages."""
    pattern = re.compile(r"""(==|in)\s*\(?\s*["'](24p|60i|50i|review|contact)["']""")
    offenders = [str(p.relative_to(ROOT)) for folder in ("shot", "telecine") for p in (ROOT / "pipeline" / folder).rglob("*.py")
                 if pattern.search(p.read_text())]
    assert offenders == []


def test_the_contact_sheet_header_is_not_cut(tmp_path: Path) -> None:
    """Two 16x12 frames made a sheet 44 pixels wide whose header line (name, frames, size,
    rate, view) ran off its right edge; the sheet is now as wide as its header."""
    from PIL import Image

    from motion.pipeline.frame_output import write_frame
    from motion.pipeline.telecine.contact_sheet import contact_sheet

    frames = tmp_path / "frames"
    for i in range(2):
        write_frame(frames / f"shot.{i:04d}.exr", np.full((12, 16, 4), 0.2, np.float32), {"frame": i}, fps=Fraction(24))
    sheet = np.asarray(Image.open(contact_sheet(frames, tmp_path / "sheet.png")).convert("L"), np.float32)
    header = sheet[:30]
    assert sheet.shape[1] > 300
    assert header[:, -3:].max() < 80  # the right margin holds no text: nothing was cut
    assert header.max() > 200  # (and there is text)


def test_quiet_after_the_command_and_the_plan_says_where_output_goes(tmp_path: Path) -> None:
    """`motion render shot.yaml -q` said "No such option: -q" (it had to come before
    `render`); the plan names the output folder and where it came from (the default is
    under the current folder, not the scene's)."""
    scene = _scene(tmp_path, last=1)
    quiet = motion("render", scene, "-o", tmp_path / "out", *TINY, "-q")
    assert quiet.returncode == 0, quiet.stderr
    assert "rendered" not in quiet.stderr  # the summary line is INFO: -q leaves warnings and errors
    loud = motion("render", scene, "-o", tmp_path / "out", *TINY)
    assert "0 rendered, 2 skipped" in loud.stderr
    plan = motion("render", scene, *TINY, "--dry-run", cwd=tmp_path)
    assert plan.returncode == 0, plan.stderr
    assert f"output:    {tmp_path / 'out' / 'farm-tiny'} (out/<name> under the current folder {tmp_path}" in plan.stdout


def test_a_frames_pixel_digest_is_its_pixels_not_its_header(tmp_path: Path) -> None:
    """The digest write_exr records (`motion:pixels_sha256`) is the picture's: two writes of
    the same pixels with other header attributes have it equal (their files differ), one
    pixel of one layer changes it, and a frame written without it (by OpenEXR alone, as
    before) is decoded to the same digest."""
    import OpenEXR

    from motion.pipeline.frame_output import META_PREFIX, PIXELS_KEY, pixel_digest, read_header, write_frame
    from motion.pipeline.identity.record import frame_pixels_digest

    rgba = np.random.default_rng(1).random((6, 8, 4)).astype(np.float32)
    normal = np.random.default_rng(2).random((6, 8, 3)).astype(np.float32)
    a = write_frame(tmp_path / "a.0001.exr", rgba, {"render_seconds": 1.5}, aovs={"normal": normal})
    b = write_frame(tmp_path / "b.0001.exr", rgba, {"render_seconds": 2.5, "worker": "w7"}, aovs={"normal": normal})
    assert a.read_bytes() != b.read_bytes()
    assert frame_pixels_digest(a) == frame_pixels_digest(b) == read_header(a)[META_PREFIX + PIXELS_KEY]
    with OpenEXR.File(str(a), separate_channels=True) as f:
        decoded = {name: np.asarray(ch.pixels) for name, ch in f.channels().items()}
    assert pixel_digest(decoded) == frame_pixels_digest(a)
    changed = normal.copy()
    changed[3, 4, 2] += 0.25
    c = write_frame(tmp_path / "c.0001.exr", rgba, {"render_seconds": 1.5}, aovs={"normal": changed})
    assert frame_pixels_digest(c) != frame_pixels_digest(a)
    bare = tmp_path / "bare.0001.exr"
    header = {k: v for k, v in read_header(a).items() if k != META_PREFIX + PIXELS_KEY and k not in ("channels", "dataWindow", "displayWindow")}
    OpenEXR.File(header, decoded).write(str(bare))
    assert META_PREFIX + PIXELS_KEY not in read_header(bare)
    assert frame_pixels_digest(bare) == frame_pixels_digest(a)


def test_a_manifest_an_earlier_motion_wrote_makes_no_version_of_an_unchanged_shot(tmp_path: Path) -> None:
    """A manifest that recorded whole files (each frame's file SHA-256, no pixel digest, as
    motion wrote before): a plain rerun is up to date (its files are the recorded ones), and
    frames rendered again make the next version, which says why without claiming that
    pixels changed; after that, versions follow pixels."""
    import hashlib

    scene, out = _scene(tmp_path, last=3), tmp_path / "out"
    args = ["render", scene, "-o", out, *TINY, "--deliver", "contact"]
    assert motion(*args).returncode == 0
    path = out / "deliver" / "manifest.json"
    doc = json.loads(path.read_text())
    v1 = doc["deliverables"]["contact"]["versions"]["v001"]
    for rec in v1["frame_files"].values():
        del rec["pixels"]
        rec["sha256"] = hashlib.sha256((out / rec["name"]).read_bytes()).hexdigest()
    del v1["timing"]
    v1["made_from"] = hashlib.sha256(json.dumps([[int(n), r["sha256"]] for n, r in v1["frame_files"].items()]).encode()).hexdigest()
    path.write_text(json.dumps(doc))
    same = motion(*args)
    assert same.returncode == 0 and "up to date (v001" in same.stderr, same.stderr
    again = motion(*args, "--overwrite", "--frames", "1")
    assert again.returncode == 0, again.stderr
    assert "(frame files rewritten or changed since v001; an earlier motion recorded whole files, not pixels)" in again.stderr, again.stderr
    assert "frames 1 changed" not in again.stderr
    last = motion(*args, "--overwrite", "--frames", "2")
    assert last.returncode == 0 and "up to date (v002" in last.stderr, last.stderr
