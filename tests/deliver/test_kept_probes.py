"""What a deliverable needs of OpenColorIO and PyAV is learnt once per config and install
(issue 46: a rerun that renders nothing within 1.5x of `motion validate`): the view's
description and the encoders' probe are kept in the cache layer (cache.STORES["probes"]),
keyed so that a changed config file or another build is probed again."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from motion.pipeline.shot.deliver import DeliverPlan, check_encoders, view_description
from motion.pipeline.shot.request import DeliverView, RenderRequest


def _request(tmp_path: Path, config: Path | str | None) -> RenderRequest:
    return RenderRequest(scene=tmp_path / "s.yaml", deliver_view=DeliverView(ocio_config=None if config is None else str(config)))


def _unbuildable(*args: object, **kwargs: object) -> None:
    raise AssertionError("the view was built again")


def test_a_kept_view_description_is_read_back_and_a_rewritten_config_is_built_again(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import PyOpenColorIO as OCIO

    import motion.pipeline.telecine.movie as movie

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    config = OCIO.Config.CreateFromFile("ocio://cg-config-latest")
    path = tmp_path / "studio.ocio"
    path.write_text(config.serialize())
    first = view_description(_request(tmp_path, path))
    assert first == movie.ViewTransform(ocio_config=str(path)).description
    with monkeypatch.context() as m:
        m.setattr(movie, "ViewTransform", _unbuildable)
        assert view_description(_request(tmp_path, path)) == first  # kept: nothing built
    # the same file, another default view (what the recipe names): seen, not the kept one
    config.setActiveViews("Un-tone-mapped")
    path.write_text(config.serialize())
    os.utime(path, ns=(path.stat().st_mtime_ns + 10**9,) * 2)
    second = view_description(_request(tmp_path, path))
    assert second != first and second.endswith("/ Un-tone-mapped, exposure +0")
    # another exposure is another description, never the kept one of exposure 0
    brighter = RenderRequest(scene=tmp_path / "s.yaml", deliver_view=DeliverView(exposure=1.0, ocio_config="none"))
    assert view_description(brighter) == "linear -> sRGB, exposure +1 stops"
    with monkeypatch.context() as m:  # `--ocio none` names no file: kept like any other view
        m.setattr(movie, "ViewTransform", _unbuildable)
        assert view_description(brighter) == "linear -> sRGB, exposure +1 stops"


def test_a_config_that_cannot_be_used_is_refused_each_time(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from motion.pipeline.errors import UsageError

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    bad = tmp_path / "bad.ocio"
    bad.write_text("not an OCIO config\n")
    for _ in range(2):  # a failure is never kept
        with pytest.raises(UsageError, match="OCIO config unusable"):
            view_description(_request(tmp_path, bad))
    assert not list((tmp_path / "cache").rglob("view*"))


def test_the_encoders_probe_is_kept_and_a_missing_encoder_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import av

    from motion.pipeline.errors import UsageError

    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    req = _request(tmp_path, "none")
    plan = DeliverPlan(("24p", "review"), explicit=True, frames=(0, 1))
    check_encoders(req, plan)  # probed: prores_ks and libx264 are in this PyAV
    assert len(list((tmp_path / "cache").rglob("encoders*"))) == 1
    with monkeypatch.context() as m:
        m.setattr(av.codec, "Codec", _unbuildable)
        check_encoders(req, plan)  # kept: not probed again
    # a build without the encoder (another key: the probe runs, and refuses)
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "other-cache"))

    def _no_codec(name: str, mode: str) -> None:
        raise av.codec.codec.UnknownCodecError(name)

    monkeypatch.setattr(av.codec, "Codec", _no_codec)
    with pytest.raises(UsageError, match="has no prores_ks encoder"):
        check_encoders(req, plan)
    assert not list((tmp_path / "other-cache").rglob("encoders*"))
