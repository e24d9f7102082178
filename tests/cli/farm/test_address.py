"""A scheduler address (farm/address.py) that cannot serve: unreachable, or a server that is
not Dask, is found in seconds, before the bake."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from farm_util import SCENE, TINY, motion


@pytest.mark.parametrize("address,says", [
    ("garbage://host:1", "unknown scheme 'garbage'"),
    ("localhost:abc", "expected tcp://HOST:PORT"),
    ("127.0.0.1:1", "cannot reach 127.0.0.1:1: Connection refused"),
    ("SCHEDFILE", "not a Dask scheduler file (not JSON"),
])
def test_an_unreachable_scheduler_is_found_in_seconds_before_the_bake(tmp_path: Path, address: str, says: str) -> None:
    if address == "SCHEDFILE":
        address = str(tmp_path / "scheduler.json")
        Path(address).write_text("not json")
    for extra in ([], ["--dry-run"]):
        t0 = time.monotonic()
        res = motion("render", SCENE, "-o", tmp_path / "out", "--scheduler", address, *TINY, *extra)
        assert time.monotonic() - t0 < 10
        assert res.returncode == 2 and says in res.stderr, res.stderr
        assert "bake:" not in res.stderr and "Traceback" not in res.stderr


def test_a_server_that_is_not_dask_is_refused_in_seconds(tmp_path: Path) -> None:
    import socket
    import threading

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(4)
    port = server.getsockname()[1]

    def speak() -> None:  # a server that greets every connection with 4 MB of noise
        for _ in range(2):
            conn, _ = server.accept()
            try:
                conn.sendall(b"\xff" * (4 << 20))
            except OSError:
                pass
            conn.close()

    threading.Thread(target=speak, daemon=True).start()
    t0 = time.monotonic()
    res = motion("render", SCENE, "-o", tmp_path / "out", "--scheduler", f"tcp://127.0.0.1:{port}", *TINY)
    assert time.monotonic() - t0 < 10
    assert res.returncode == 2 and "answers, but not as a Dask scheduler" in res.stderr, res.stderr
    server.close()
