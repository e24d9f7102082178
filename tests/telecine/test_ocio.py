"""The OCIO view transform, for real: PyOpenColorIO's built-in configs (ocio://...), no mocks.

Known values: the cg config's "Un-tone-mapped" view on the "sRGB - Display" is the sRGB
curve itself (IEC 61966-2-1), and its default view, ACES 2.0 SDR 100 nits, puts scene
mid grey 0.18 at 10 nits, i.e. display-linear 0.1, sRGB-encoded 0.34919.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import av
import matplotlib.image
import numpy as np
import pytest

from motion.cli.main import main
from motion.pipeline.errors import UsageError
from motion.pipeline.frame_output import write_frame
from motion.pipeline.telecine.contact_sheet import contact_sheet
from motion.pipeline.telecine.movie import TRC_SRGB, ViewTransform, srgb_encode

CONFIG = "ocio://cg-config-latest"
MID_GREY_ACES2 = float(srgb_encode(np.array(0.10)))  # 0.349190


def rgba(values: list[float]) -> np.ndarray:
    x = np.asarray(values, np.float32)
    return np.stack([x, x, x, np.ones_like(x)], axis=-1)


def test_defaults_come_from_the_config_and_frames_are_linear_rec709() -> None:
    view = ViewTransform(ocio_config=CONFIG)
    # Default display and view are the config's; our frames are linear Rec.709 (not ACEScg,
    # the config's scene_linear role).
    assert view.display == "sRGB - Display" and view.view.startswith("ACES 2.")
    assert view.source == "Linear Rec.709 (sRGB)" and view.color_tags == (1, TRC_SRGB)
    out = view.encode(rgba([0.0, 0.18]))
    assert out[0].tolist() == [0, 0, 0]
    np.testing.assert_allclose(out[1], MID_GREY_ACES2, atol=5e-4)
    # Exposure applies before the view: 0.09 at +1 stop is 0.18.
    np.testing.assert_allclose(ViewTransform(1.0, CONFIG).encode(rgba([0.09]))[0], out[1], atol=1e-6)


def test_untonemapped_srgb_view_is_the_srgb_curve() -> None:
    view = ViewTransform(ocio_config=CONFIG, ocio_display="sRGB - Display", ocio_view="Un-tone-mapped")
    x = [0.0, 1e-4, 0.0031308, 0.01, 0.18, 0.5, 0.9, 1.0, 4.0]  # toe, knee, mid, clipped
    np.testing.assert_allclose(view.encode(rgba(x))[:, 0], srgb_encode(np.asarray(x)), atol=2e-5)
    # Colorimetric: a pure Rec.709 red stays pure red (it would not if read as ACEScg).
    red = view.encode(np.array([[0.18, 0.0, 0.0, 1.0]], np.float32))[0]
    np.testing.assert_allclose(red, [srgb_encode(np.array(0.18)), 0, 0], atol=2e-5)
    # Quantised like the built-in path.
    assert np.abs(view(rgba(x)).astype(int) - ViewTransform(ocio_config="none")(rgba(x)).astype(int)).max() <= 2


def test_bad_ocio_requests_are_usage_errors() -> None:
    with pytest.raises(UsageError, match="cg-config-v"):  # lists the built-in names
        ViewTransform(ocio_config="ocio://no-such-config")
    with pytest.raises(UsageError, match="has no view 'Nope'; it has .*Un-tone-mapped"):
        ViewTransform(ocio_config=CONFIG, ocio_view="Nope")
    with pytest.raises(UsageError, match="no OCIO display 'Nope'"):
        ViewTransform(ocio_config=CONFIG, ocio_display="Nope")
    with pytest.raises(UsageError, match="need an OCIO config"):
        ViewTransform(ocio_config="none", ocio_view="Un-tone-mapped")


def test_movie_and_contact_sheet_through_builtin_config(tmp_path: Path) -> None:
    levels = [0.05, 0.18, 0.6]
    for i, v in enumerate(levels):
        write_frame(tmp_path / "in" / f"g.{i + 1:04d}.exr", np.full((16, 32, 4), v, np.float32), fps=Fraction(24))
    movie = tmp_path / "g.mov"
    # Through the CLI: the URI must reach OCIO intact (a Path would make it ocio:/...).
    assert main(["telecine", str(tmp_path / "in"), "-o", str(tmp_path / "60i"), "--movie", str(movie),
                 "--ocio", CONFIG]) == 0
    expected = ViewTransform(ocio_config=CONFIG).encode(rgba(levels))[:, 0]
    assert abs(expected[1] - MID_GREY_ACES2) < 5e-4 and abs(expected[1] - srgb_encode(np.array(0.18))) > 0.1
    with av.open(str(movie)) as container:
        stream = container.streams.video[0]
        assert stream.codec_context.color_trc == TRC_SRGB
        decoded = [f.to_ndarray(format="rgb48le").astype(np.float64) / 65535 for f in container.decode(stream)]
    # 3 film frames -> 4 video frames (pad tail): A, B, B|C, C (top|bottom)
    assert len(decoded) == 4
    for frame, (top, bottom) in zip(decoded, [(0, 0), (1, 1), (1, 2), (2, 2)]):
        # Every pixel of each field, within ~1.5 steps of ProRes' 10-bit video-range luma.
        assert np.abs(frame[0::2] - expected[top]).max() < 1.5e-3
        assert np.abs(frame[1::2] - expected[bottom]).max() < 1.5e-3
    sheet = contact_sheet(tmp_path / "in", tmp_path / "s.png", thumb_width=32, columns=3, view=ViewTransform(ocio_config=CONFIG))
    img = matplotlib.image.imread(sheet)
    y0 = 30 + 4
    for k in range(3):
        assert abs(img[y0 + 8, 4 + k * 36 + 16, 0] - expected[k]) <= 1 / 255


def test_the_default_view_keeps_a_bright_sky_from_clipping() -> None:
    """The deliverables' default view is OCIO's ACES 2.0 SDR (a tone curve): an HDR sky of
    1.5-6 scene-linear clips under 1% of its pixels (the plain sRGB curve clipped them all)."""
    import numpy as np

    from motion.pipeline.telecine.movie import ViewTransform

    sky = np.ones((64, 64, 4), np.float32)
    sky[..., 0], sky[..., 1], sky[..., 2] = np.linspace(1.5, 4.0, 64)[:, None], np.linspace(2.0, 5.0, 64)[:, None], np.linspace(3.0, 6.0, 64)[:, None]
    clipped = lambda view: float((view.encode(sky) >= 1.0 - 1e-6).any(axis=-1).mean())  # noqa: E731
    assert clipped(ViewTransform()) < 0.01
    assert clipped(ViewTransform(ocio_config="none")) == 1.0
    assert "ACES 2.0" in ViewTransform().description
