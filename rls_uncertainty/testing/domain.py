"""A ROS domain of its own for a live test (:func:`claim_domain`).

A live test's node and player must be the only participants on their domain: another node
named ``rls_estimator`` there (a second test session, an orphaned node, someone's demo) would
hear the bag and publish on the same topics, and the test would pass or fail with its
numbers. A claim of domain ``D`` takes two steps, in this order:

1. **A lock**: an exclusive ``flock`` on ``<tempdir>/rls_uncertainty_domains/domain-D.lock``
   (:data:`LOCK_DIR`; the directory is world-writable with the sticky bit, like ``/tmp``, so
   every user's sessions on the machine share it). Processes that claim domains this way never
   hold the same one; the kernel drops the lock when the holder exits, whatever ends it, so a
   killed session leaves nothing to clean up. The holder's pid is written in the file, for the
   message of the next one.
2. **A look at the graph**: a node of its own on ``D`` watches the ROS graph for
   :data:`PROBE_SECONDS` (or until it sees another node): any other node there means someone
   who does not take the lock (another tool, a node left running) uses the domain.

A domain that fails either step is skipped and the next of the range is tried; when none is
left, :class:`..errors.ConfigError` says in one line what each one held and which option
gives others. The claim is held until :meth:`DomainClaim.release` (or the process's end).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

from ..errors import ConfigError

__all__ = ["DEFAULT_DOMAINS", "LOCK_DIR", "PROBE_SECONDS", "DomainClaim", "claim_domain", "domain_ids", "lock_domain"]

DEFAULT_DOMAINS = "42-49"
LOCK_DIR = Path(tempfile.gettempdir()) / "rls_uncertainty_domains"
# How long the graph of a domain is watched for other nodes. A new look saw a node already
# running on its domain after 0.5 to 2.1 s (six looks on loopback, 2 cores at load average 5.5).
PROBE_SECONDS = 3.0


def domain_ids(spec: str, ambient: str | None = None) -> list[int]:
    """The domain ids of ``FIRST-LAST`` (or one id) other than ``ambient`` (the environment's
    ``ROS_DOMAIN_ID``, 0 when unset); a :class:`..errors.ConfigError` when none is left."""
    first, _, last = spec.strip().partition("-")
    try:
        lo, hi = int(first), int(last or first)
    except ValueError:
        raise ConfigError(f"rls_domains: expected FIRST-LAST (e.g. {DEFAULT_DOMAINS}), got {spec!r}") from None
    if not 0 <= lo <= hi <= 232:
        raise ConfigError(f"rls_domains: ROS domain ids are 0 to 232 with FIRST <= LAST, got {spec!r}")
    ambient = ambient if ambient is not None else os.environ.get("ROS_DOMAIN_ID", "0")
    left = [d for d in range(lo, hi + 1) if str(d) != ambient.strip()]
    if not left:
        raise ConfigError(f"rls_domains {spec!r}: only the environment's own ROS_DOMAIN_ID; give others")
    return left


class DomainClaim:
    """Domain :attr:`domain`, held by this process (its lock file open) until :meth:`release`."""

    def __init__(self, domain: int, fd: int) -> None:
        self.domain = domain
        self._fd: int | None = fd

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor drops the flock
            self._fd = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def __enter__(self) -> DomainClaim:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _lock_dir() -> Path:
    LOCK_DIR.mkdir(mode=0o1777, exist_ok=True)
    with contextlib.suppress(OSError):  # another user's directory: theirs to set
        if LOCK_DIR.stat().st_uid == os.getuid():
            LOCK_DIR.chmod(0o1777)
    return LOCK_DIR


def _lock(domain: int) -> tuple[int | None, str]:
    """The locked descriptor of ``domain``'s lock file, or None and who holds it."""
    path = _lock_dir() / f"domain-{domain}.lock"
    try:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
        except PermissionError:  # another user's file: a read-only descriptor locks as well
            fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    except OSError as exc:
        return None, f"not lockable ({path}: {exc.strerror})"
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "?"
        os.close(fd)
        return None, f"held by process {holder}"
    with contextlib.suppress(OSError):  # read-only: the pid stays unsaid
        if os.fstat(fd).st_uid == os.getuid():
            os.fchmod(fd, 0o666)
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
    return fd, ""


def other_nodes(domain: int, seconds: float = PROBE_SECONDS) -> list[str]:
    """The fully qualified names of the nodes seen on ``domain`` within ``seconds`` (returning
    at the first one), this look's own node left out."""
    import rclpy  # noqa: PLC0415 - ROS only for a live test

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    try:
        node = rclpy.create_node("rls_testing_domain_probe", context=context, enable_rosout=False,
                                 start_parameter_services=False)
        try:
            me = (node.get_name(), node.get_namespace())
            deadline = time.monotonic() + seconds
            while True:
                seen = [f"{ns.rstrip('/')}/{name}" for name, ns in node.get_node_names_and_namespaces()
                        if (name, ns) != me]
                if seen or time.monotonic() >= deadline:
                    return sorted(seen)
                time.sleep(0.05)  # the graph is filled by rmw's own threads
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def lock_domain(ids: Sequence[int]) -> DomainClaim | None:
    """The first of ``ids`` that this process can lock (step 1 of a claim, without the look at
    the graph), held until released; None when every one is held."""
    for domain in ids:
        fd, _why = _lock(domain)
        if fd is not None:
            return DomainClaim(domain, fd)
    return None


def claim_domain(ids: Sequence[int], *, probe: float = PROBE_SECONDS,
                 advice: str = "pass other domain ids") -> DomainClaim:
    """The first of ``ids`` that this process can lock and on which no other node is seen
    (module docstring); :class:`..errors.ConfigError` naming each one's holder, then
    ``advice``, when none is free."""
    busy = []
    for domain in ids:
        fd, why = _lock(domain)
        if fd is None:
            busy.append(f"{domain} {why}")
            continue
        try:
            seen = other_nodes(domain, probe)
        except BaseException:
            os.close(fd)
            raise
        if not seen:
            return DomainClaim(domain, fd)
        os.close(fd)
        more = f" and {len(seen) - 3} more" if len(seen) > 3 else ""
        busy.append(f"{domain} has node(s) {', '.join(seen[:3])}{more}")
    raise ConfigError(f"no free ROS domain for the node under test: {'; '.join(busy)}; {advice}")
