"""`--scheduler`: parse the address (or scheduler file) and probe it in a few seconds,
before the bake and in `--dry-run`, so a typo or a farm that is down is one line at once,
not a 30-second wait after the simulation (or a hang inside Dask on a server that is not
Dask's).

The probe opens a TCP connection and reads what the server says first: a Dask scheduler
greets every new connection with its handshake (a msgpack map naming `compression` and
`python`: distributed.comm.core.Comm.handshake_info). Nothing is sent and at most 4 KiB are
read, so a foreign server cannot make us allocate or wait beyond the timeout.
"""

from __future__ import annotations

import json
import os
import socket
import time
from pathlib import Path
from urllib.parse import urlsplit

from ..errors import UsageError

SCHEMES = ("tcp", "tls")
PROBE_TIMEOUT_S = 3.0
MAX_SCHEDULER_FILE = 1 << 20  # bytes: a scheduler file is a few hundred


def parse_address(text: str, what: str = "--scheduler") -> tuple[str, str, int]:
    """'tcp://host:8786' (or 'host:8786') -> (scheme, host, port); UsageError naming what
    is wrong (scheme, host, port) otherwise."""
    spec = text.strip()
    if "://" not in spec:
        malformed = _malformed_scheme(spec)
        if malformed is not None:
            raise UsageError(f"{what} {text!r}: the scheme is malformed (a scheme ends in '://'); did you mean {malformed!r}?")
        spec = f"tcp://{spec}"
    try:
        parts = urlsplit(spec)
        port = parts.port
    except ValueError as exc:
        raise UsageError(f"{what} {text!r}: {exc}; expected tcp://HOST:PORT") from None
    if parts.scheme not in SCHEMES:
        from ..scene.problems import closest

        close = closest(parts.scheme, list(SCHEMES))
        hint = f"; did you mean {close + spec[len(parts.scheme):]!r}?" if close else f"; expected {' or '.join(s + '://' for s in SCHEMES)}HOST:PORT"
        raise UsageError(f"{what} {text!r}: unknown scheme '{parts.scheme}'{hint}")
    if not parts.hostname:
        raise UsageError(f"{what} {text!r}: no host; expected tcp://HOST:PORT")
    if port is None or not 1 <= port <= 65535:
        raise UsageError(f"{what} {text!r}: no port; expected tcp://HOST:PORT with a port from 1 to 65535")
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        raise UsageError(f"{what} {text!r}: unexpected '{parts.path or ''}{'?' + parts.query if parts.query else ''}' after the port; expected tcp://HOST:PORT")
    return parts.scheme, parts.hostname, port


def _malformed_scheme(spec: str) -> str | None:
    """The address `spec` meant when it starts with a scheme whose '://' is written wrong
    ('tcp//h:p', 'tcp:/h:p', 'tcp:h:p', 'tpc//h:p'), else None. Only a known scheme (or a
    near misspelling of one) counts: 'host:8786' has no scheme and is fine."""
    import re

    from ..scene.problems import closest

    m = re.match(r"([A-Za-z][A-Za-z0-9+.-]*)(:/*|/+)(.+)$", spec)
    if m is None:
        return None
    scheme = closest(m.group(1), list(SCHEMES), cutoff=0.6)
    if scheme is None or (m.group(2) == ":" and m.group(1).lower() not in SCHEMES) or (m.group(2) == ":" and m.group(3).isdigit()):
        return None
    return f"{scheme}://{m.group(3).lstrip('/')}"


def read_scheduler_file(path: Path) -> str:
    """The address a Dask scheduler file (`dask scheduler --scheduler-file F`) holds."""
    try:
        if not path.is_file():
            raise UsageError(f"--scheduler {path}: not a regular file")
        if path.stat().st_size > MAX_SCHEDULER_FILE:
            raise UsageError(f"--scheduler {path}: {path.stat().st_size} bytes is not a scheduler file (at most {MAX_SCHEDULER_FILE})")
        data = json.loads(path.read_text())
    except OSError as exc:
        raise UsageError(f"--scheduler {path}: cannot read it: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise UsageError(f"--scheduler {path}: not a Dask scheduler file (not JSON: {exc})") from None
    address = data.get("address") if isinstance(data, dict) else None
    if not isinstance(address, str):
        raise UsageError(f"--scheduler {path}: not a Dask scheduler file (no \"address\" string)")
    return address


def scheduler_target(spec: str) -> dict[str, str]:
    """`tcp://host:port` (or `host:port`) -> {address}; an existing file -> {scheduler_file},
    its address checked. UsageError for anything else."""
    if "://" not in spec and (os.path.lexists(spec) or spec.endswith(".json")):
        path = Path(spec)
        if not os.path.lexists(spec):
            raise UsageError(f"--scheduler {spec}: no such scheduler file")
        parse_address(read_scheduler_file(path), f"--scheduler {spec}: address")
        return {"scheduler_file": spec}
    scheme, host, port = parse_address(spec)
    return {"address": f"{scheme}://{host}:{port}"}


def probe_scheduler(spec: str, timeout_s: float = PROBE_TIMEOUT_S) -> str:
    """Parse `spec` and check, within `timeout_s`, that a Dask scheduler answers there.
    Returns the address; UsageError (one line: what, where, why) otherwise."""
    target = scheduler_target(spec)
    address = target.get("address") or read_scheduler_file(Path(target["scheduler_file"]))
    scheme, host, port = parse_address(address, f"--scheduler {spec}")
    t0 = time.monotonic()
    try:
        with socket.create_connection((host, port), timeout=timeout_s) as sock:
            if scheme == "tls":
                return address  # the greeting is encrypted; reaching the port is what we can check
            sock.settimeout(max(0.1, timeout_s - (time.monotonic() - t0)))
            greeting = b""
            while len(greeting) < 4096 and not (b"compression" in greeting and b"python" in greeting):
                chunk = sock.recv(4096 - len(greeting))
                if not chunk:
                    break
                greeting += chunk
    except socket.timeout:
        raise UsageError(f"--scheduler {spec}: {host}:{port} did not answer within {timeout_s:g} s "
                         f"(is a Dask scheduler running there? `dask scheduler --port {port}`)") from None
    except OSError as exc:
        why = exc.strerror or type(exc).__name__
        raise UsageError(f"--scheduler {spec}: cannot reach {host}:{port}: {why} (is a Dask scheduler running there? `dask scheduler --port {port}`)") from None
    if not (b"compression" in greeting and b"python" in greeting):
        raise UsageError(f"--scheduler {spec}: {host}:{port} answers, but not as a Dask scheduler")
    return address
