"""`--transfer`: shared (workers read the scene and write frames by path), ship (the job
carries its inputs: shipment.py) or auto (ship when one worker does not see the client's
scene file and output folder: `workers_see`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ...write_policy import write_atomic
from ...render.worker.job import RenderJob
from ...scene.files import readable_digests
from ...scene.loader import LoadedScene
from .shipment import ship_job


def workers_see(target: dict[str, Any], scene_file: str | Path, out_dir: str | Path) -> bool:
    """Whether the cluster's workers see the client's folders (`--transfer auto`): one
    worker hashes, at the client's paths, the scene file and a probe file the client has just
    written into the output folder; both must match. A cluster with no worker within 60 s
    counts as seeing them (the executor then waits and fails in one line)."""
    import uuid

    from distributed import Client

    scene = str(Path(scene_file).resolve())
    probe = Path(out_dir).resolve() / f".motion-transfer-probe-{uuid.uuid4().hex[:12]}"
    write_atomic(probe, uuid.uuid4().hex.encode(), "probing whether the workers see the output folder")
    try:
        with Client(**target, timeout=30, set_as_default=False) as client:
            try:
                client.wait_for_workers(1, timeout=60)
            except Exception:  # dask's own TimeoutError type
                return True
            workers = sorted(client.scheduler_info(n_workers=-1)["workers"])
            got = client.run(readable_digests, [scene, str(probe)], workers=workers[:1])
        return next(iter(got.values())) == readable_digests([scene, str(probe)])
    finally:
        probe.unlink(missing_ok=True)


def choose_transfer(mode: str, target: dict[str, Any], job: RenderJob, loaded: LoadedScene) -> RenderJob:
    """`--transfer`: shared keeps the job as it is (workers read the scene and write frames
    by path); ship makes it carry its inputs (`ship_job`); auto ships when a worker does not
    see the scene file or the output folder the client sees."""
    if mode == "shared" or (mode == "auto" and workers_see(target, loaded.path, job.output_dir)):
        return job
    return ship_job(job, loaded, loaded.path)
