"""The job as ship mode sends it (`ship_job`: the parsed scene and its manifest, no bytes),
where a worker fetches the bytes it lacks from (`FilesByHash` on the client, `BytesByHash`
of what came with a chunk), and the client's side of the Dask scatter (`Shipment`: each
file crosses to each worker once)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterable

from ...errors import AssetError
from ...render.worker.job import RenderJob
from ...scene.files import bytes_digest
from ...scene.loader import LoadedScene
from .localize import localize
from .manifest import ShippedAsset, asset_manifest, ship_imports
from .store import missing_assets


class BytesByHash(dict):  # type: ignore[type-arg]
    """Asset bytes by content hash held in this process: the source `localize` fetches from
    when the client's own process (or a local worker it forked) renders a shipped job."""

    def __call__(self, sha256: str) -> bytes:
        """The bytes with this hash."""
        return bytes(self[sha256])


@dataclass
class ShippedScene:
    """A job's scene as it travels in ship mode: the parsed scene (no worker parses it
    again), its asset manifest, and where a worker fetches the bytes it lacks from
    (the client's `FilesByHash`; on a worker, `BytesByHash` of what came with the chunk)."""

    loaded: LoadedScene
    assets: tuple[ShippedAsset, ...]
    fetch: Callable[[str], bytes] = field(repr=False)

    def checkout(self) -> LoadedScene:
        """The scene with its assets resolved to this worker's cached copies (`localize`)."""
        return localize(self.loaded, self.assets, self.fetch)


def ship_job(job: RenderJob, loaded: LoadedScene, scene_file: str | Path) -> RenderJob:
    """The job as ship mode sends it: the parsed scene and its asset manifest ride along
    (their bytes read when a worker first lacks them: `Shipment`). Raises AssetError for a file
    outside the scene's folder before anything is read or sent."""
    scene, sources = ship_imports(loaded.scene, loaded.base_dir)
    assets = tuple(asset_manifest(scene, loaded.base_dir, scene_file, sources))
    return replace(job, shipped=ShippedScene(replace(loaded, scene=scene), assets, FilesByHash(loaded.base_dir, assets, sources)))


def with_payload(job: RenderJob, payload: dict[str, bytes]) -> RenderJob:
    """The shipped job as a worker runs it: the asset bytes that came with its chunk (those
    its cache lacked) are where `localize` fetches from."""
    shipped = job.shipped
    if not isinstance(shipped, ShippedScene):
        return job
    return replace(job, shipped=replace(shipped, fetch=BytesByHash(payload)))


class FilesByHash:
    """Asset bytes on the client, read from the scene's folder when a worker first needs
    them (nothing is held in memory meanwhile) and checked against the manifest's hash."""

    def __init__(self, base_dir: Path, assets: Iterable[ShippedAsset], sources: dict[str, Path] | None = None) -> None:
        """Where the files lie: each one's scene-relative name by content hash, under the
        scene's folder or, for a converted import file, where `sources` says."""
        sources = sources or {}
        self.path = {a.sha256: sources.get(a.rel, Path(base_dir) / a.rel) for a in assets}

    def __call__(self, sha256: str) -> bytes:
        """The file's bytes; AssetError when it changed since the job was planned."""
        path = self.path[sha256]
        data = path.read_bytes()
        if bytes_digest(data) != sha256:
            raise AssetError(f"{path}: changed while the job runs (its hash is no longer {sha256[:16]}); run motion render again")
        return data


class Shipment:
    """The client's side of one shipped job on a Dask cluster: the job as sent (the parsed
    scene and manifest, without bytes) scattered once, and which workers already hold every
    asset. A worker's first chunk asks it what it lacks (`missing_assets`, one `client.run`:
    nothing when its renderer holds this job's scene built, else what its cache lacks) and takes exactly those assets as futures among its arguments: an asset
    is scattered when a worker first lacks it, to every worker at once (`broadcast`: a
    scattered asset cannot be recomputed, so one held by a single worker would die with it
    and cancel the chunks elsewhere that needed it), so each asset crosses to each worker
    once, never once per frame, and not at all when every disk cache kept it from an
    earlier job. The futures are held while the job runs (the cluster drops data nobody holds)."""

    def __init__(self, client: Any, job: RenderJob) -> None:
        """Scatter the job as sent."""
        shipped = job.shipped
        if not isinstance(shipped, ShippedScene):
            raise TypeError("Shipment needs a job made by ship_job")
        self.given = job
        self.assets = shipped.assets
        self.fetch = shipped.fetch
        self.futures: dict[str, Any] = {}
        self.sent = with_payload(job, {})
        # the job (parsed scene, settings) crosses once per worker too: tasks carry its key.
        # On every worker (broadcast): scattered data cannot be recomputed, so a job held by
        # one worker alone died with it, and every chunk running elsewhere was "lost" with it
        # (retried with no cause: test_a_worker_killed_mid_chunk_is_retried, 1 run in 2)
        self._job_future = client.scatter(self.sent, hash=False, broadcast=True)
        self.stocked: set[str] = set()  # workers that hold every asset (cache or sent)
        self.bytes_sent = 0  # asset bytes handed to workers (each once per worker, every worker once one lacks it)
        self.holders: dict[str, set[str]] = {}  # asset -> the workers it was sent to
        self._sizes = {a.sha256: a.size for a in self.assets}
        self.bytes_scattered = 0  # asset bytes the client itself uploaded

    def job_future(self, client: Any) -> Any:
        """The scattered job, scattered again if every worker holding it has died."""
        if self._job_future.status != "finished":
            self._job_future = client.scatter(self.sent, hash=False, broadcast=True)
        return self._job_future

    def _future(self, client: Any, sha256: str, worker: str) -> Any:
        """The asset's future for `worker`: scattered now if no live worker holds it (to every
        worker, as the job: scattered data cannot be recomputed, and an asset held by the one
        worker that first lacked it died with that worker, cancelling every chunk elsewhere
        that still needed it from there), else taken from a holder. Counts what crosses."""
        if sha256 not in self.futures or self.futures[sha256].status != "finished":  # new, or every holder died
            data = self.fetch(sha256)
            self.futures[sha256] = client.scatter(data, hash=False, broadcast=True)
            self.holders[sha256] = set(client.scheduler_info(n_workers=-1).get("workers", {})) | {worker}
            self.bytes_scattered += len(data)
            self.bytes_sent += len(data) * len(self.holders[sha256])
        elif worker not in self.holders.setdefault(sha256, set()):  # a worker that joined since: from a holder
            self.holders[sha256].add(worker)
            self.bytes_sent += self._sizes[sha256]
        return self.futures[sha256]

    def payload_for(self, client: Any, worker: str) -> dict[str, Any]:
        """The asset futures `worker` still needs (empty once it holds every asset)."""
        if worker in self.stocked:
            return {}
        everything = sorted({a.sha256 for a in self.assets})
        try:
            warm = self.given.key if self.given.cache else None
            lacking = client.run(missing_assets, self.assets, warm, workers=[worker]).get(worker, everything)
        except Exception:  # the worker left or cannot answer: send everything (the chunk is retried if it is gone)
            lacking = everything
        self.stocked.add(worker)
        return {h: self._future(client, h, worker) for h in lacking}

    def stats(self) -> dict[str, int]:
        """The job's assets: how many, their total size, the bytes handed to workers and
        the bytes the client uploaded."""
        return {"assets": len(self.assets), "asset_bytes": sum(a.size for a in self.assets), "asset_bytes_to_workers": self.bytes_sent,
                "asset_bytes_from_client": self.bytes_scattered, "workers_stocked": len(self.stocked)}

    def forget(self, worker: str) -> None:
        """A worker lost a chunk (it may have restarted, its cache gone): ask it again."""
        self.stocked.discard(worker)
