"""Reports of a comparison that CI systems and people read: an HTML page, JUnit XML (one
test case per frame), JSON, and the one-line summary (`Comparison.summary`).

The HTML report is one page in a folder with its images (relative links, so the folder is
a CI artifact as it is): the summary, which variant made which frames, a table of every
frame, and for each frame that differs its reference and new frame in one viewer (hover to
see the reference, click to pin it; `#frame=N&show=ref` opens so), the difference map, the
FLIP map and the map of block z-scores, with the regions that differ marked on each. The
images go through the plain sRGB view (telecine.movie.ViewTransform, `--ocio none`).
"""

from __future__ import annotations

import datetime as _dt
import html
import io
import json
import math
import re
import socket
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import UsageError
from ..write_policy import write_atomic
from ..timeline import format_frames
from .comparison import Comparison, FrameOutcome

# characters XML 1.0 cannot hold (a control character in a file name): shown as U+FFFD
_NOT_XML = re.compile("[^\\t\\n\\r\\x20-\\ud7ff\\ue000-\\ufffd\\U00010000-\\U0010ffff]")


def _xml(text: object) -> str:
    """`text` as XML 1.0 can hold it."""
    return _NOT_XML.sub("\ufffd", str(text))


def write_junit(comparison: Comparison, path: str | Path) -> Path:
    """JUnit XML (Jenkins' junit-10.xsd, which GitHub Actions, GitLab and Jenkins read): one
    test suite, one test case per frame; a frame that differs or is missing is a failure
    whose message is its one line and whose text lists its regions; each note (how the
    frames were made differently) is a property of the suite and a line of its frames."""
    counts = comparison.counts()
    failures = counts["different"] + counts["missing"]
    name = f"motion compare {comparison.new_dir} vs {comparison.ref_dir}"
    e = _xml
    suites = ET.Element("testsuites", name="motion compare", tests=str(len(comparison.frames)), failures=str(failures), errors="0", time=f"{comparison.seconds:.3f}")
    suite = ET.SubElement(suites, "testsuite", name=e(name), tests=str(len(comparison.frames)), failures=str(failures), errors="0", skipped="0",
                          time=f"{comparison.seconds:.3f}", timestamp=_dt.datetime.now().replace(microsecond=0).isoformat(), hostname=socket.gethostname())
    props = ET.SubElement(suite, "properties")
    for key, value in (("new", comparison.new_dir), ("reference", comparison.ref_dir), ("variants", json.dumps(comparison.variants())),
                       ("allowed_differences", "; ".join(comparison.notes) or "none")):
        ET.SubElement(props, "property", name=key, value=e(value))
    for note in comparison.notes:
        ET.SubElement(props, "property", name="note", value=e(note))
    prefix = Path(comparison.frames[0].ref).name.split(".")[0] if comparison.frames else "frames"
    for f in comparison.frames:
        case = ET.SubElement(suite, "testcase", classname=e(f"motion.compare.{prefix}"), name=f"frame {f.frame:04d}", time=f"{f.seconds:.3f}")
        if f.failed:
            failure = ET.SubElement(case, "failure", type=f.outcome, message=e(f.message()))
            failure.text = e(_details(f))
        else:
            out = ET.SubElement(case, "system-out")
            out.text = e(_details(f))
    ET.indent(suites)
    data = ET.tostring(suites, encoding="utf-8", xml_declaration=True)
    return write_atomic(path, data + b"\n", "writing JUnit report")


def _details(f: FrameOutcome) -> str:
    lines = [f.message()]
    if f.outcome != "missing":
        lines.append(f"tested layer {f.layer}; largest |z| {f.max_z:.2f}, threshold {f.threshold:.2f}, kappa {f.kappa:.2f}")
        lines.append("new: variant {v}, seed {s}, spp {p}; reference: variant {rv}, seed {rs}, spp {rp}".format(
            v=f.new_facts.get("variant"), s=f.new_facts.get("seed"), p=f.new_facts.get("spp"),
            rv=f.ref_facts.get("variant"), rs=f.ref_facts.get("seed"), rp=f.ref_facts.get("spp")))
    for r in f.regions:
        lines.append(f"  region {r.describe()}")
    lines.extend(f"note: {note}" for note in f.notes)
    return "\n".join(lines)


def _finite(value: Any) -> Any:
    """`value` with every NaN or infinite number as null (JSON has no token for them)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def write_json(comparison: Comparison, path: str | Path) -> Path:
    """The whole comparison as JSON (Comparison.to_dict; a NaN or infinite figure, such as
    the z of a non-finite pixel, is null)."""
    return write_atomic(path, (json.dumps(_finite(comparison.to_dict()), indent=1, allow_nan=False) + "\n").encode(), "writing compare report")


def _png(rgb8: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb8)).save(buf, format="PNG")
    return buf.getvalue()


def _view(rgba: np.ndarray) -> np.ndarray:
    from ..telecine.export import to_8bit
    from ..telecine.movie import ViewTransform

    return to_8bit(ViewTransform(ocio_config="none")(rgba))


def _magma(x: np.ndarray) -> np.ndarray:
    """[H, W] in [0, 1] -> uint8 RGB through matplotlib's magma colour map (FLIP's own)."""
    from matplotlib import colormaps

    return (colormaps["magma"](np.clip(x, 0.0, 1.0))[..., :3] * 255.0 + 0.5).astype(np.uint8)


def _frame_images(f: FrameOutcome) -> dict[str, bytes]:
    """PNG bytes of the reference, the new frame, |difference|, FLIP and z maps."""
    from ..frame_output import read_frame

    new, ref = (np.nan_to_num(read_frame(p).rgba, nan=0.0, posinf=0.0, neginf=0.0) for p in (f.new, f.ref))  # type: ignore[arg-type]
    diff = np.abs(new[..., :3].astype(np.float64) - ref[..., :3]).max(axis=2)
    scale = float(np.quantile(diff, 0.999)) or 1.0  # (finite: non-finite values are 0 here)
    out = {"ref": _png(_view(ref)), "new": _png(_view(new)), "diff": _png(_magma(diff / scale))}
    if f.flip_map is not None:
        out["flip"] = _png(_magma(f.flip_map))
    if f.z_blocks is not None:
        h, w = new.shape[:2]
        z = np.repeat(np.repeat(f.z_blocks / max(f.threshold, 1e-9), f.block, 0), f.block, 1)[:h, :w]
        out["z"] = _png(_magma(z / 2.0))  # the threshold at mid-scale
    return out


_STYLE = """
body { font: 14px/1.4 system-ui, sans-serif; margin: 1.5em; background: #15161a; color: #ddd; }
a { color: #8cf; } h1 { font-size: 1.3em; } h2 { font-size: 1.1em; margin-top: 2em; }
table { border-collapse: collapse; } td, th { padding: 2px 8px; border-bottom: 1px solid #333; text-align: left; }
.identical, .equal { color: #7c7; } .different, .missing { color: #f66; font-weight: bold; }
.maps { display: flex; flex-wrap: wrap; gap: 12px; }
figure { margin: 0; width: 31%; min-width: 240px; } figcaption { font-size: 12px; color: #aaa; }
.pane { position: relative; line-height: 0; cursor: pointer; }
.pane img { width: 100%; image-rendering: pixelated; }
.swap .ref { position: absolute; left: 0; top: 0; opacity: 0; }
.swap:hover .ref, .swap.showing-ref .ref { opacity: 1; }
.region { position: absolute; border: 2px solid #0ff; box-sizing: border-box; pointer-events: none; }
.region span { position: absolute; top: -1.4em; left: 0; font-size: 11px; line-height: 1.2; color: #0ff; background: #000a; padding: 0 3px; }
"""

_SCRIPT = """
(function () {
  var loaded = 0, broken = 0, imgs = document.querySelectorAll('img');
  function done() {
    document.body.dataset.loaded = loaded;
    if (broken) document.body.dataset.broken = broken;
  }
  imgs.forEach(function (img) {
    if (img.complete && img.naturalWidth > 0) loaded++;
    else if (img.complete) broken++;
    else {
      img.addEventListener('load', function () { loaded++; done(); });
      img.addEventListener('error', function () { broken++; done(); });
    }
  });
  done();
  function show(swap, ref) {
    swap.classList.toggle('showing-ref', ref);
    swap.parentNode.querySelector('.which').textContent = ref ? 'reference' : 'new';
    swap.dataset.showing = ref ? 'ref' : 'new';
  }
  document.querySelectorAll('.swap').forEach(function (swap) {
    swap.addEventListener('click', function () { show(swap, !swap.classList.contains('showing-ref')); });
    swap.addEventListener('mouseenter', function () { swap.parentNode.querySelector('.which').textContent = 'reference'; });
    swap.addEventListener('mouseleave', function () { show(swap, swap.classList.contains('showing-ref')); });
  });
  var args = {};
  location.hash.replace(/^#/, '').split('&').forEach(function (kv) { var p = kv.split('='); if (p[0]) args[p[0]] = p[1]; });
  if (args.frame) {
    var sec = document.getElementById('frame-' + args.frame);
    if (sec) {
      sec.scrollIntoView();
      document.body.dataset.frame = args.frame;
      if (args.show === 'ref') show(sec.querySelector('.swap'), true);
    }
  }
})();
"""


def _regions_html(f: FrameOutcome, h: int, w: int) -> str:
    boxes = []
    for i, r in enumerate(f.regions[:8]):
        style = f"left:{100 * r.x0 / w:.3f}%;top:{100 * r.y0 / h:.3f}%;width:{100 * (r.x1 - r.x0) / w:.3f}%;height:{100 * (r.y1 - r.y0) / h:.3f}%"
        boxes.append(f'<div class="region" style="{style}" title="{html.escape(r.describe())}"><span>{i + 1}</span></div>')
    return "".join(boxes)


def write_html(comparison: Comparison, folder: str | Path) -> Path:
    """The HTML report in `folder` (index.html and img/), returning the page's path."""
    folder = Path(folder)
    (folder / "img").mkdir(parents=True, exist_ok=True)
    e = html.escape
    counts = comparison.counts()
    rows = []
    sections = []
    for f in comparison.frames:
        worst = e(f.regions[0].describe()) if f.regions else ""
        flip = f"{f.flip:.3f}" if f.flip is not None else ""
        noted = f' title="{e("; ".join(f.notes))}"' if f.notes else ""
        link = f'<a href="#frame={f.frame}">{f.frame}</a>' if f.outcome == "different" else str(f.frame)
        rows.append(f'<tr id="row-{f.frame}"{noted}><td>{link}</td><td class="{f.outcome}">{f.outcome}</td>'
                    f'<td>{e(str(f.new_facts.get("variant", "")))}</td><td>{e(str(f.ref_facts.get("variant", "")))}</td>'
                    f'<td>{e(str(f.new_facts.get("seed", "")))} / {e(str(f.ref_facts.get("seed", "")))}</td>'
                    f'<td>{f.layer}</td><td>{f.max_z:.1f} / {f.threshold:.1f}</td><td>{flip}</td><td>{worst}</td></tr>')
        if f.outcome != "different" or f.new is None:
            continue
        images = _frame_images(f)
        for kind, data in images.items():
            write_atomic(folder / "img" / f"{f.frame:06d}-{kind}.png", data, "writing compare report image")
        h, w = int(f.new_facts["resolution"][1]), int(f.new_facts["resolution"][0])
        marks = _regions_html(f, h, w)
        src = lambda kind: f"img/{f.frame:06d}-{kind}.png"  # noqa: E731
        figs = [f'<figure><div class="pane swap" data-showing="new"><img class="new" src="{src("new")}" alt="new"><img class="ref" src="{src("ref")}" alt="reference">{marks}</div>'
                f'<figcaption>showing <b class="which">new</b> (hover: reference, click: pin)</figcaption></figure>',
                f'<figure><div class="pane"><img src="{src("diff")}" alt="difference">{marks}</div><figcaption>|new - reference|, largest channel (scaled to its 99.9th percentile)</figcaption></figure>']
        if "flip" in images:
            figs.append(f'<figure><div class="pane"><img src="{src("flip")}" alt="FLIP">{marks}</div><figcaption>FLIP map (mean {f.flip:.3f})</figcaption></figure>')
        if "z" in images:
            figs.append(f'<figure><div class="pane"><img src="{src("z")}" alt="z">{marks}</div><figcaption>block |z| (threshold {f.threshold:.1f} at mid-scale)</figcaption></figure>')
        regions = "".join(f"<li>{e(r.describe())}</li>" for r in f.regions)
        sections.append(f'<section id="frame-{f.frame}" class="frame"><h2>Frame {f.frame}: <span class="different">different</span></h2>'
                        f'<p>new {e(str(f.new))} (variant {e(str(f.new_facts.get("variant")))}), reference {e(str(f.ref))} '
                        f'(variant {e(str(f.ref_facts.get("variant")))}); tested layer {f.layer}</p><ol>{regions}</ol><div class="maps">{"".join(figs)}</div></section>')
    variants = "".join(f"<li>{e(v)}: {len(fr)} frame(s) ({e(format_frames(fr))})</li>" for v, fr in comparison.variants().items())
    allowed = "".join(f"<li>{e(a)}</li>" for a in comparison.notes)
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>motion compare: {e(str(comparison.new_dir))}</title><style>{_STYLE}</style></head>
<body data-failed="{len(comparison.failed)}">
<h1 id="summary" class="{'different' if comparison.failed else 'equal'}">{e(comparison.summary())}</h1>
<p>new frames <code>{e(str(comparison.new_dir))}</code>, references <code>{e(str(comparison.ref_dir))}</code>.
{counts['identical']} identical, {counts['equal']} equal within noise, {counts['different']} different, {counts['missing']} missing.</p>
<h2>Variants of the new frames</h2><ul id="variants">{variants}</ul>
{f'<h2>Made differently from the references (compared all the same)</h2><ul id="allowed">{allowed}</ul>' if allowed else ''}
<table id="frames"><tr><th>frame</th><th>outcome</th><th>variant (new)</th><th>variant (ref)</th><th>seed new / ref</th><th>layer</th><th>|z| / threshold</th><th>FLIP</th><th>worst region</th></tr>
{''.join(rows)}</table>
{''.join(sections)}
<script>{_SCRIPT}</script>
</body></html>
"""
    return write_atomic(folder / "index.html", page.encode(), "writing compare report")


def _blocking_ancestor(path: Path) -> Path | None:
    """The nearest existing folder above `path` when it is not a folder (a file stands where
    a folder must be made), else None."""
    for parent in path.absolute().parents:
        if parent.exists() or parent.is_symlink():
            return None if parent.is_dir() else parent
    return None


def check_report_targets(*, html_dir: str | Path | None = None, junit: str | Path | None = None, json_path: str | Path | None = None, what: str | None = None) -> None:
    """Before any work: every report can be written where asked (a file where a file goes,
    folders where folders go), creating nothing. UsageError naming the path (and `what`
    asked for it, else the flag) otherwise."""
    wanted: list[tuple[Path, bool, str]] = []  # (path, is a folder, which report)
    if html_dir is not None:
        wanted += [(Path(html_dir), True, "--html/--report"), (Path(html_dir) / "index.html", False, "--html/--report"),
                   (Path(html_dir) / "img", True, "--html/--report")]
    if junit is not None:
        wanted.append((Path(junit), False, "--junit/--report"))
    if json_path is not None:
        wanted.append((Path(json_path), False, "--json/--report"))
    for path, folder, flag in wanted:
        flag = what or flag
        if path.exists() and path.is_dir() != folder:
            raise UsageError(f"{flag} {path}: cannot write the report there: it is {'a file, not a folder' if folder else 'a folder, not a file'}")
        blocking = _blocking_ancestor(path)
        if blocking is not None:
            raise UsageError(f"{flag} {path}: cannot write the report there: {blocking} is a file, not a folder")


def write_reports(comparison: Comparison, *, html_dir: str | Path | None = None, junit: str | Path | None = None, json_path: str | Path | None = None) -> dict[str, Any]:
    """Write the reports asked for; returns {kind: path}."""
    out: dict[str, Any] = {}
    if html_dir is not None:
        out["html"] = str(write_html(comparison, html_dir))
    if junit is not None:
        out["junit"] = str(write_junit(comparison, junit))
    if json_path is not None:
        out["json"] = str(write_json(comparison, json_path))
    return out
