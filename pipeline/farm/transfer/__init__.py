"""Jobs that carry their inputs, frames that come home (docs/farm.md, "A farm without a
shared disk"), one concern per module:

- `manifest`: what a shipped job carries (every file the scene names, by content hash,
  refused before anything is read when it lies outside the scene's folder).
- `store`: the worker's content-addressed store of the files it received, bounded by
  $MOTION_ASSET_CACHE_CAP and reused across jobs.
- `localize`: the parsed scene as a worker renders it, its relative paths resolved to the
  store's copies.
- `shipment`: the job as it travels (`ship_job`, `ShippedScene`) and the client's side of
  the Dask scatter (`Shipment`, `FilesByHash`).
- `home`: chunks claimed on the client, rendered in the worker's own folder, published home.
- `choose`: `--transfer` shared, ship or auto (`workers_see`).
"""
