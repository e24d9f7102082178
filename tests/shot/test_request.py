"""The render request holds each `motion render` option as a typed field, never as a dict key."""

from __future__ import annotations

import dataclasses
from pathlib import Path


def test_the_deliverables_view_options_are_typed_fields_of_the_request(tmp_path: Path) -> None:
    """--exposure and the --ocio options reach the deliverables' view as the fields of
    `DeliverView` (each one an option of the command), and make its ViewTransform."""
    from motion.cli.render import render
    from motion.pipeline.shot import DeliverView, RenderRequest
    from motion.pipeline.shot.deliver import deliver_view

    options = {p.name for p in render.params}
    fields = {f.name for f in dataclasses.fields(DeliverView)}
    assert fields == {"exposure", "ocio_config", "ocio_display", "ocio_view"} and fields <= options
    assert RenderRequest(scene=tmp_path / "s.yaml").deliver_view == DeliverView()
    view = deliver_view(RenderRequest(scene=tmp_path / "s.yaml", deliver_view=DeliverView(exposure=1.0, ocio_config="none")))
    assert float(view.gain) == 2.0 and "+1 stops" in view.description
