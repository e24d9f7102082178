"""Jobs that carry their inputs, frames that come home (docs/farm.md, "A farm without a
shared disk"). The client lists every file the scene names by SHA-256 content hash
(refusing, before anything is read or sent, a file outside the scene's folder) and scatters
the bytes once per job through Dask (`Shipment`); each worker keeps what it receives in an
on-disk content-addressed cache bounded by $MOTION_ASSET_CACHE_CAP and reused across jobs,
and resolves the scene's relative asset paths to its cached copies (`localize`). Chunks
render into the worker's own temporary folder and return the checked EXR bytes
(`run_chunk_away`); the client claims, resume-checks and publishes the frames under `-o`
(`claim_home`, `publish_home`). `--transfer auto` asks one worker to hash the scene file
(`workers_see`)."""

from __future__ import annotations

import hashlib
import os
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from ..cache import STORES
from ..bake import BakedFrame
from ..errors import AssetError, DiskFaultError
from ..frame_output import is_complete
from ..render.job import FrameResult, RenderJob, expected_meta
from ..files import confined, write_atomic, writing
from ..limits import env_size

STORE = STORES["shipped"]
from ..scene.files import NamedFile, bytes_digest, file_digest, named_files, readable_digests, renamed
from ..scene.imports.cache import converted_file
from ..scene.loader import LoadedScene
from ..scene.schema import Scene
from ..scene.source import yaml_path
from .claims import release
from .task import ChunkResult, TaskContext, claim_frame


@dataclass(frozen=True)
class ShippedAsset:
    """One file a shipped job carries: its path relative to the scene's folder (as the
    scene names it), its SHA-256 content hash and its size in bytes."""

    rel: str
    sha256: str
    size: int


IMPORTED = ".motion-imports"  # where a shipped job's converted import files are named, in the scene's folder


def ship_imports(scene: Scene, base_dir: Path) -> tuple[Scene, dict[str, Path]]:
    """The scene with every file that import expansion made (a glTF or USD mesh converted
    into motion's own import cache, named there by an absolute path) renamed to
    `.motion-imports/<name>`, a path inside the scene's folder as a shipped job carries it;
    and where each renamed file lies on this machine. Those files are ours, converted from
    sources inside the scene's folder that the import stage opened and checked."""
    sources: dict[str, Path] = {}

    def carried(named: NamedFile) -> str | None:
        path = Path(base_dir) / named.rel
        if not converted_file(path):
            return None
        name = f"{IMPORTED}/{path.name}"
        sources[name] = path.resolve()
        return name

    return renamed(scene, carried), sources


def asset_manifest(scene: Scene, base_dir: Path, scene_file: str | Path, sources: dict[str, Path] | None = None) -> list[ShippedAsset]:
    """Every file the scene names (`named_files`, the asset checks' own walk), each once, by
    content hash. A path that leads outside the scene's folder (`..`, an absolute path, a
    link) raises AssetError naming the scene file and the YAML path, before any file is read:
    a shipped job never carries the client's other files to the cluster. `sources`: where
    the converted import files (`ship_imports`) lie."""
    base = Path(base_dir)
    sources = sources or {}
    named = list(named_files(scene))
    for loc, rel, _kind, _deforming in named:
        if rel not in sources and not _inside(base, base / rel):
            raise AssetError(f"{scene_file}: {yaml_path(loc)}: {rel} lies outside the scene's folder {base.resolve()}; a shipped job sends only files inside it")
    out: dict[str, ShippedAsset] = {}
    for _loc, rel, _kind, _deforming in named:
        if rel not in out:
            path = sources.get(rel, base / rel)
            out[rel] = ShippedAsset(rel, file_digest(path), path.stat().st_size)  # hashed once per run: the settings hash read it too
    return list(out.values())


def _inside(base: Path, path: Path) -> bool:
    """Whether `path`, every link on it followed (its last part too: an asset that is a link
    to a file elsewhere is outside), lies inside `base`."""
    root, real = base.resolve(), path.resolve()
    return real == root or root in real.parents


def shipped_cache_dir() -> Path:
    """The worker's cache of shipped assets (under the cache root), one file per content hash."""
    return STORE.dir()


def _entry(folder: Path, sha256: str, rel: str) -> Path:
    """A cache entry's path: the hash, with the suffix the scene's file had (the mesh and
    image loaders choose their reader by it)."""
    return folder / (sha256 + Path(rel).suffix.lower())


def store(sha256: str, data: bytes, folder: Path | None = None, rel: str = "") -> Path:
    """Keep `data` in the content-addressed cache as `<folder>/<sha256><suffix of rel>` and
    return its path.
    Bytes that do not hash to `sha256` (damaged in transit) raise AssetError and are not
    kept; a full cache disk raises the one-line DiskFaultError (pipeline/files.py); the cache
    is then held to $MOTION_ASSET_CACHE_CAP, least recently used first, keeping this entry."""
    folder = folder if folder is not None else shipped_cache_dir()
    got = bytes_digest(data)
    if got != sha256:
        raise AssetError(f"shipped asset {sha256[:16]}: received {len(data)} bytes hashing to {got[:16]}; expected the file with hash {sha256[:16]}")
    target = _entry(folder, sha256, rel)
    STORE.make(target, lambda tmp: tmp.write_bytes(data), "caching a shipped asset")
    return target


def cached(asset: ShippedAsset, folder: Path | None = None) -> Path | None:
    """The cached copy of `asset` when this worker already holds it whole and it is ours
    (a file another user planted under that hash is not used), marked as just used so the
    cap evicts others first; else None."""
    path = _entry(folder if folder is not None else shipped_cache_dir(), asset.sha256, asset.rel)
    return path if STORE.hit(path, lambda p: p.stat().st_size == asset.size) else None


def check_out(assets: Iterable[ShippedAsset], fetch: Callable[[str], bytes], folder: Path | None = None) -> dict[str, Path]:
    """Each asset's local path on this worker, by the path the scene names it with: a cached
    copy when there is one, else `fetch(sha256)` (the scattered bytes) stored first. Only
    missing assets are fetched, so a worker receives each file once across jobs."""
    out: dict[str, Path] = {}
    for asset in assets:
        path = cached(asset, folder)
        if path is None:
            try:
                data = fetch(asset.sha256)
            except KeyError:
                raise AssetError(f"shipped asset {asset.rel} ({asset.sha256[:16]}): not in this worker's cache and not sent with the chunk") from None
            path = store(asset.sha256, data, folder, asset.rel)
        out[asset.rel] = path
    return out


def checkout_folder(assets: Iterable[ShippedAsset], folder: Path | None = None) -> Path:
    """Where a job's checkout lives on this worker: one folder per manifest (the same
    assets by the same names share it across jobs), beside the cached entries."""
    return (folder if folder is not None else shipped_cache_dir()) / "checkouts" / manifest_key(assets)


def manifest_key(assets: Iterable[ShippedAsset]) -> str:
    """A short digest of a manifest (each file's scene-relative name and content hash)."""
    return hashlib.sha256("\n".join(sorted(f"{a.rel}\0{a.sha256}" for a in assets)).encode()).hexdigest()[:24]


def localize(loaded: LoadedScene, assets: Sequence[ShippedAsset], fetch: Callable[[str], bytes], folder: Path | None = None) -> LoadedScene:
    """The parsed scene as this worker renders it: every asset checked out of the cache
    (`check_out`) and linked under its scene-relative name in a checkout folder, which
    becomes the scene's folder, so each path the scene names resolves to the cached copy.
    The scene is not parsed again. A job whose assets alone exceed $MOTION_ASSET_CACHE_CAP
    raises AssetError (the cap would evict a file the job is about to read)."""
    cap = env_size("MOTION_ASSET_CACHE_CAP")
    total = sum(a.size for a in assets)
    if total > cap:
        raise AssetError(f"{loaded.path}: the scene's {len(assets)} files take {total} bytes, more than MOTION_ASSET_CACHE_CAP={cap} on this worker; raise it")
    root = folder if folder is not None else shipped_cache_dir()
    paths = check_out(assets, fetch, root)
    home = checkout_folder(assets, root)
    for rel, target in paths.items():
        link = home / rel
        if not confined(home, link):
            raise AssetError(f"{loaded.path}: {rel} lies outside the scene's folder; a shipped job uses only files inside it")
        if link.is_symlink() and link.resolve() == target.resolve():
            continue
        link.parent.mkdir(parents=True, exist_ok=True)
        tmp = link.with_name(f".{link.name}.{os.getpid()}.link")
        tmp.unlink(missing_ok=True)
        tmp.symlink_to(target.resolve())
        os.replace(tmp, link)  # another process checking out the same manifest sees one link or the other
    return replace(loaded, path=home / loaded.path.name)


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


def missing_assets(assets: Sequence[ShippedAsset]) -> list[str]:
    """The hashes of `assets` this worker's cache does not hold whole (run on a worker by
    `client.run` before its first chunk of a job: only those bytes are sent to it)."""
    return sorted({a.sha256 for a in assets if cached(a) is None})


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
    asset. A worker's first chunk asks its cache what it lacks (`missing_assets`, one
    `client.run`) and takes exactly those assets as futures among its arguments: an asset
    is scattered (`client.scatter`, to that worker) when a worker first lacks it, and Dask
    moves it to every later one (from any worker holding it), so each asset crosses to each
    worker once, never once per frame, and not at all when every disk cache kept it from an
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
        # the job (parsed scene, settings) crosses once per worker too: tasks carry its key
        self._job_future = client.scatter(self.sent, hash=False)
        self.stocked: set[str] = set()  # workers that hold every asset (cache or sent)
        self.bytes_sent = 0  # asset bytes handed to workers (each once per worker)
        self.bytes_scattered = 0  # asset bytes the client itself uploaded

    def job_future(self, client: Any) -> Any:
        """The scattered job, scattered again if every worker holding it has died."""
        if self._job_future.status != "finished":
            self._job_future = client.scatter(self.sent, hash=False)
        return self._job_future

    def _future(self, client: Any, sha256: str, worker: str) -> Any:
        if sha256 not in self.futures or self.futures[sha256].status != "finished":  # new, or every holder died
            data = self.fetch(sha256)
            try:
                self.futures[sha256] = client.scatter(data, workers=[worker], hash=False)
            except KeyError:  # that worker just left the cluster: anywhere will do
                self.futures[sha256] = client.scatter(data, hash=False)
            self.bytes_scattered += len(data)
        return self.futures[sha256]

    def payload_for(self, client: Any, worker: str) -> dict[str, Any]:
        """The asset futures `worker` still needs (empty once it holds every asset)."""
        if worker in self.stocked:
            return {}
        everything = sorted({a.sha256 for a in self.assets})
        try:
            lacking = client.run(missing_assets, self.assets, workers=[worker]).get(worker, everything)
        except Exception:  # the worker left or cannot answer: send everything (the chunk is retried if it is gone)
            lacking = everything
        self.stocked.add(worker)
        sizes = {a.sha256: a.size for a in self.assets}
        self.bytes_sent += sum(sizes[h] for h in lacking)
        return {h: self._future(client, h, worker) for h in lacking}

    def stats(self) -> dict[str, int]:
        """The job's assets: how many, their total size, the bytes handed to workers and
        the bytes the client uploaded."""
        return {"assets": len(self.assets), "asset_bytes": sum(a.size for a in self.assets), "asset_bytes_to_workers": self.bytes_sent,
                "asset_bytes_from_client": self.bytes_scattered, "workers_stocked": len(self.stocked)}

    def forget(self, worker: str) -> None:
        """A worker lost a chunk (it may have restarted, its cache gone): ask it again."""
        self.stocked.discard(worker)


def claim_home(job: RenderJob, inputs: Sequence[BakedFrame], ctx: TaskContext) -> tuple[list[BakedFrame], ChunkResult]:
    """On the client, before a shipped chunk is sent: the usual claims and resume check on
    the output folder (`task.claim_frame`), which the workers cannot see. Returns the frames
    to render remotely (claimed by this run) and a result holding the others (held by
    another render, already complete, refused); a disk fault stops there."""
    from ..render.job import worker_id
    from .claims import Claimant

    me = Claimant.here(ctx.run_id)
    pre = ChunkResult(chunk_id=-1, worker=worker_id())
    todo: list[BakedFrame] = []
    for baked in inputs:
        try:
            if claim_frame(job, baked, ctx, me, pre):
                todo.append(baked)
        except DiskFaultError as exc:
            pre.disk_fault = str(exc)
            break
    return todo, pre


def run_chunk_away(run: Callable[[int, RenderJob, Sequence[BakedFrame], TaskContext], ChunkResult], chunk_id: int, job: RenderJob, inputs: Sequence[BakedFrame], ctx: TaskContext) -> ChunkResult:
    """A chunk on a worker that cannot see the output folder: `run` renders it into a
    temporary folder of the worker's own (the client holds the real claims), each finished
    EXR is read back (`is_complete`: whole, and its header carries this job's hashes) and
    its bytes go home in the result for the client to publish (`publish_home`). A disk
    fault here is this worker's own disk (its asset cache, its temporary folder): the frame
    fails with that one line and is retried on another worker; only the client's output
    disk stops the job."""
    with tempfile.TemporaryDirectory(prefix="motion-ship-") as tmp:
        here = {b.frame: str(Path(tmp) / Path(ctx.paths[b.frame]).name) for b in inputs}
        res = run(chunk_id, replace(job, output_dir=tmp), inputs, replace(ctx, paths=here, resume=False))
        by_frame = {b.frame: b for b in inputs}
        for r in res.results:
            if r.disk_fault or not r.ok:
                if r.disk_fault:
                    r.disk_fault, r.error = False, f"on worker {res.worker}: {r.error}"
                continue
            if not is_complete(r.path, expected_meta(job, by_frame[r.frame])):
                r.ok, r.error = False, f"frame {r.frame}: the EXR written on worker {res.worker} did not read back whole; not sent"
                continue
            res.frame_bytes[r.frame] = Path(r.path).read_bytes()
        if res.disk_fault:
            done = {r.frame for r in res.results}
            res.results.extend(FrameResult(b.frame, "", False, res.worker, error=f"on worker {res.worker}: {res.disk_fault}") for b in inputs if b.frame not in done)
            res.disk_fault = None
    return res


def publish_home(pre: ChunkResult, res: ChunkResult, job: RenderJob, ctx: TaskContext) -> ChunkResult:
    """On the client: publish each frame a shipped chunk brought home at its planned path
    under the output folder, atomically and read back (pipeline/files.py), release this
    run's claims, and merge what `claim_home` settled before sending. A frame reported
    written whose bytes did not arrive is failed (the farm retries it as after a lost
    worker); a disk fault on the output folder marks the result so the farm stops as for
    any disk fault."""
    res.held_elsewhere.update(pre.held_elsewhere)
    res.already_done.extend(pre.already_done)
    res.results.extend(pre.results)
    res.disk_fault = res.disk_fault or pre.disk_fault
    unsent: list[FrameResult] = []
    for r in res.results:
        data = res.frame_bytes.pop(r.frame, None)
        path = ctx.paths[r.frame]
        try:
            if res.disk_fault and r.ok:
                unsent.append(r)  # the output disk refused an earlier frame: not rendered, kept for a rerun
                continue
            if not r.ok:
                continue
            if data is None:
                r.ok, r.error = False, f"frame {r.frame}: rendered on {res.worker} but its EXR was lost on the way back"
            elif not confined(job.output_dir, path):
                r.ok, r.error = False, f"{path}: a link on its way leads outside the output folder {job.output_dir}; not written"
            else:
                with writing(path, "publishing a frame a worker sent", verify=lambda tmp, data=data: tmp.read_bytes() == data) as tmp:
                    tmp.write_bytes(data)
                r.path = path
        except DiskFaultError as exc:
            r.ok, r.error, r.disk_fault = False, str(exc), True
            res.disk_fault = str(exc)
        finally:
            release(path, ctx.run_id)
    res.frame_bytes.clear()
    res.results = [r for r in res.results if r not in unsent]
    return res


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
