"""The render stage's tables: the AOV table (render/kernel/aovs.py) against the scene format and
the film's channel layout, and the per-frame data blocks (render/poses/kernel.py) refusing a
frame of the wrong shape with a named error."""

from __future__ import annotations

import typing

import numpy as np
import pytest

from motion.pipeline.errors import FrameDataError, RendererError
from motion.pipeline.render.kernel import aovs
from motion.pipeline.scene.schema import OutputSettings


def test_the_aov_table_names_exactly_what_a_scene_may_ask_for() -> None:
    (item,) = typing.get_args(OutputSettings.model_fields["aovs"].annotation)
    assert set(typing.get_args(item)) == set(aovs.BY_NAME)


def test_channels_follow_the_table_order_whatever_order_they_are_asked_in() -> None:
    assert aovs.channel_names(["albedo", "depth"]) == ["Z", "albedo.R", "albedo.G", "albedo.B"]
    assert aovs.channel_names(["motion", "normal"]) == ["N.X", "N.Y", "N.Z", "motion.X", "motion.Y"]
    assert aovs.channel_names([]) == []


def test_split_layers_cuts_the_film_image_by_the_table() -> None:
    wanted = ["motion", "depth", "albedo", "normal"]
    names = aovs.channel_names(wanted)
    image = np.arange(2 * 3 * (4 + len(names)), dtype=np.float32).reshape(2, 3, 4 + len(names))
    rgba, layers = aovs.split_layers(image, wanted)
    assert rgba.shape == (2, 3, 4) and np.array_equal(rgba, image[..., :4])
    assert list(layers) == ["Z", "N", "motion", "albedo"]
    assert layers["Z"].shape == (2, 3)  # a one-channel layer is a plane
    assert layers["N"].shape == (2, 3, 3) and layers["motion"].shape == (2, 3, 2) and layers["albedo"].shape == (2, 3, 3)
    # every channel lands once, in the film's order after RGBA
    flat = np.concatenate([layers["Z"][..., None], layers["N"], layers["motion"], layers["albedo"]], axis=2)
    assert np.array_equal(flat, image[..., 4:])


@pytest.mark.render
def test_a_frame_of_the_wrong_shape_is_a_frame_data_error() -> None:
    from _render_support import activate

    activate()
    import mitsuba as mi

    from motion.pipeline.render.kernel.integrator import register

    register()
    integrator = mi.load_dict({"type": "motion_path"})
    integrator.set_samples(3)
    n = 3
    good = (np.zeros((0, n, 3)), np.zeros((0, n, 4)), np.zeros((n, 3)), np.tile([1.0, 0, 0, 0], (n, 1)), np.zeros(3))
    integrator.set_frame(*good)  # the shapes of its job: accepted
    with pytest.raises(FrameDataError, match="'camera_t' has shape \\(2, 3\\), expected \\(3, 3\\)") as caught:
        integrator.set_frame(good[0], good[1], np.zeros((2, 3)), *good[3:])
    assert isinstance(caught.value, RendererError)


@pytest.mark.render
def test_fewer_than_one_sample_per_pixel_is_a_sample_count_error() -> None:
    from _render_support import activate

    activate()
    import mitsuba as mi

    from motion.pipeline.errors import SampleCountError
    from motion.pipeline.render.kernel.integrator import register

    register()
    scene = mi.load_dict({"type": "scene", "integrator": {"type": "motion_path"}, "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4}}})
    scene.integrator().set_samples(2)
    scene.integrator().set_frame(np.zeros((0, 2, 3)), np.zeros((0, 2, 4)), np.zeros((2, 3)), np.tile([1.0, 0, 0, 0], (2, 1)), np.zeros(3))
    with pytest.raises(SampleCountError, match="at least 1 sample per pixel, got -1"):
        scene.integrator().render(scene, spp=-1)
    image = np.array(scene.integrator().render(scene, spp=1))  # one is enough
    assert image.shape == (4, 4, 4)
