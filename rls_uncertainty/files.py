"""Writing outputs without ever losing data: the one write-then-rename helper of the package.

* :func:`atomic_file` writes one file: a new temporary file is created exclusively in the
  target's directory (a fresh random name, so a planted file or symlink is never opened or
  written through), given the replaced file's permissions (a new file those of ``open``),
  flushed and fsync'ed, then renamed over the target, and the directory is fsync'ed. On any
  failure the temporary file is removed and the target is untouched.
* :func:`temporaries` lists the temporary files :func:`atomic_file` leaves when a write is
  interrupted (a crash, a kill): exactly its own name pattern ``.NAME.<16 hex digits>.tmp``
  beside ``NAME`` (and ``.NAME.<8 of [a-z0-9_]>.tmp``, the names versions up to 0.1.0 made with
  ``tempfile.mkstemp``), regular files only, so a caller that holds the target's lock may
  remove them.
* :class:`FileLock` is an exclusive lock on a lock file beside a target (``.NAME.lock``, never
  renamed): ``flock``, so the operating system releases it when its process ends, however it
  ends. It is taken without waiting; the holder's process id is written in it, for the message
  of the process that finds it taken. Its holder removes it when done, and a taker checks
  that the file it locked is still the one at the path, so removing it never lets two
  processes hold it.
* :func:`output_directory` builds an output directory (a bag, a replay's results) in a new
  temporary directory beside it and renames it into place only when complete. It refuses an
  output that would destroy data the command did not create: an existing file, a non-empty
  directory (unless ``force``), and, even with ``force``, a path that is, contains or lies
  inside one of the command's inputs. Paths are resolved (symlinks, ``..``) before they are
  compared. On any failure everything the command created is removed, and nothing else,
  Ctrl-C or a signal the command turns into an exception included. The temporary directory
  ``.NAME.<8 characters>.partial`` is ``flock``-ed while it is written; one that a killed
  process left (SIGKILL, a power cut: nothing runs to remove it) is unlocked, and the next
  call for the same output removes it (:func:`stale_partials`) before it starts.
* :func:`input_problem` says why a path cannot be an input, without opening it: a FIFO, a
  device or a socket (a reader would block on it or read it without end), a symbolic link
  loop, a missing path; :func:`file_kind` names what a file is.
* :class:`OutputWriter` is the base of the writers used in a ``with`` block (a bag, an MCAP
  file, a replay's outputs): completed by ``close`` when the block ends normally, discarded by
  ``abort`` when it raises.
"""

from __future__ import annotations

import errno
import fcntl
import os
import re
import secrets
import shutil
import stat
import tempfile
from abc import ABC, abstractmethod
from collections.abc import Iterable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from types import TracebackType
from typing import IO, Self

from .errors import OutputPathError

__all__ = ["atomic_file", "temporaries", "FileLock", "file_kind", "input_problem", "output_directory",
           "stale_partials", "OutputWriter"]

# atomic_file's temporary names beside NAME, and those of versions up to 0.1.0 (tempfile.mkstemp).
_TEMPORARY = r"\.{name}\.(?:[0-9a-f]{{16}}|[a-z0-9_]{{8}})\.tmp"


def _fsync_directory(directory: Path) -> None:
    with suppress(OSError):  # not every file system lets a directory be opened or synced
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _umask() -> int:
    """The process's umask, read without changing it where the system tells (Linux)."""
    with suppress(OSError, ValueError), open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _new_file_mode(target: Path) -> int:
    """The permissions the file gets: those of the regular file it replaces, else what
    ``open(path, "w")`` would give (0666 less the umask), not mkstemp's private 0600."""
    with suppress(OSError):
        st = os.lstat(target)
        if stat.S_ISREG(st.st_mode):
            return stat.S_IMODE(st.st_mode)
    return 0o666 & ~_umask()


def _new_temporary(target: Path, directory: Path) -> tuple[int, Path]:
    """A new temporary file ``.NAME.<16 hex digits>.tmp`` beside ``target``, created
    exclusively (never a file or link that is there already), and its descriptor."""
    flags = os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0)
    for _ in range(100):
        tmp = directory / f".{target.name}.{secrets.token_hex(8)}.tmp"
        try:
            return os.open(tmp, flags, 0o600), tmp
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, f"no free temporary name beside {target}")


def temporaries(path: str | os.PathLike[str]) -> list[Path]:
    """The temporary files an interrupted :func:`atomic_file` of ``path`` left beside it: its
    name pattern only, regular files only (no link, directory or anything else), sorted."""
    target = Path(path)
    directory = target.parent if str(target.parent) else Path(".")
    pattern = re.compile(_TEMPORARY.format(name=re.escape(target.name)))
    found = []
    with suppress(FileNotFoundError, NotADirectoryError), os.scandir(directory) as entries:
        for entry in entries:
            if pattern.fullmatch(entry.name) and entry.is_file(follow_symlinks=False):
                found.append(directory / entry.name)
    return sorted(found)


@contextmanager
def atomic_file(path: str | os.PathLike[str]) -> Iterator[IO[bytes]]:
    """Yield a binary file whose content replaces ``path`` atomically when the block ends."""
    target = Path(path)
    directory = target.parent if str(target.parent) else Path(".")
    fd, tmp = _new_temporary(target, directory)
    try:
        with os.fdopen(fd, "wb") as fh:
            os.fchmod(fh.fileno(), _new_file_mode(target))
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)  # renames over a symlink itself, never through it
    except BaseException:
        with suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    _fsync_directory(directory)


class FileLock:
    """An exclusive lock on ``.NAME.lock`` beside ``path``, taken at construction without
    waiting (see the module docstring); :meth:`release` (or the end of the process) frees it.

    Raises :class:`BlockingIOError` when another process holds it (its ``strerror`` says
    ``held by process PID``, as the lock file says), and :class:`OSError` when the lock file
    cannot be made or is not a regular file. The lock file is opened
    without following a link and without waiting (a FIFO planted at its name cannot block)."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        target = Path(path)
        self.path = target.with_name(f".{target.name}.lock")
        flags = os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
        for _ in range(100):
            fd = os.open(self.path, flags, 0o666 & ~_umask())
            try:
                if not stat.S_ISREG(os.fstat(fd).st_mode):
                    raise OSError(errno.EINVAL, "the lock file is not a regular file", str(self.path))
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
                    who = f"process {holder}" if holder.isdigit() else "another process"
                    raise BlockingIOError(errno.EWOULDBLOCK, f"held by {who}", str(self.path)) from None
                if self._same_file(fd):
                    os.ftruncate(fd, 0)
                    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
                    self._fd: int | None = fd
                    return
            except BaseException:
                os.close(fd)
                raise
            os.close(fd)  # its holder removed it after we opened it: lock the new one
        raise OSError(errno.EAGAIN, "the lock file keeps being replaced", str(self.path))

    def _same_file(self, fd: int) -> bool:
        """Whether the locked file is still the one at :attr:`path`."""
        try:
            st = os.stat(self.path, follow_symlinks=False)
        except FileNotFoundError:
            return False
        mine = os.fstat(fd)
        return (st.st_dev, st.st_ino) == (mine.st_dev, mine.st_ino)

    @property
    def held(self) -> bool:
        return self._fd is not None

    def release(self) -> None:
        """Remove the lock file (while still holding it) and free the lock; idempotent."""
        fd, self._fd = self._fd, None
        if fd is None:
            return
        try:
            if self._same_file(fd):
                with suppress(OSError):
                    os.unlink(self.path)
        finally:
            os.close(fd)


_KINDS = ((stat.S_ISREG, "a regular file"), (stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def file_kind(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, in words (``a FIFO``)."""
    return next((name for test, name in _KINDS if test(mode)), "a special file")


def input_problem(path: str | os.PathLike[str], *, directory: bool = True) -> str | None:
    """Why ``path`` cannot be read as an input, in words, or None when it is a regular file
    (or, with ``directory``, a directory): missing, a symbolic link loop, unreadable, or a
    FIFO, device or socket, which a reader would block on or read without end. Symbolic links
    are followed; nothing is opened."""
    try:
        mode = os.stat(path).st_mode
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return "a symbolic link loop"
        if exc.errno == errno.ENOENT:
            return "no such file or directory"
        return f"cannot be read ({exc.strerror or exc})"
    if stat.S_ISREG(mode) or (directory and stat.S_ISDIR(mode)):
        return None
    return f"{file_kind(mode)}, not a regular file{' or a directory' if directory else ''}"


def _inside(path: Path, other: Path) -> bool:
    return path == other or other in path.parents


def _first_missing_ancestor(path: Path) -> Path | None:
    missing = None
    for p in (path, *path.parents):
        if p.exists():
            break
        missing = p
    return missing


def _lock_directory(path: Path) -> int | None:
    """A descriptor of the directory ``path`` holding an exclusive ``flock`` on it, taken
    without waiting; None when another process holds it (or it cannot be opened)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        return None
    return fd


def stale_partials(path: str | os.PathLike[str]) -> list[Path]:
    """The unfinished outputs of ``path`` whose writer is gone: the ``.NAME.<8 characters>.partial``
    directories beside it (:func:`output_directory`'s name pattern, directories only) that no
    process holds locked. :func:`output_directory` locks its directory while it writes, and the
    operating system releases the lock when the process ends, however it ends (a SIGKILL, a
    power cut): a directory found unlocked is one no process will finish. Sorted."""
    target = Path(path)
    directory = target.parent if str(target.parent) else Path(".")
    pattern = re.compile(rf"\.{re.escape(target.name)}\.[a-z0-9_]{{8}}\.partial")
    found = []
    with suppress(OSError), os.scandir(directory) as entries:
        for entry in entries:
            if pattern.fullmatch(entry.name) and entry.is_dir(follow_symlinks=False):
                fd = _lock_directory(directory / entry.name)
                if fd is not None:
                    os.close(fd)
                    found.append(directory / entry.name)
    return sorted(found)


def _replace_with(tmp: Path, final: Path, given: Path) -> None:
    """``final`` (a directory) replaced by ``tmp``; should the swap fail, the old one is put back."""
    old = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".old", dir=final.parent))
    try:
        os.rename(final, old / final.name)
    except BaseException:
        old.rmdir()
        raise
    try:
        os.rename(tmp, final)
    except BaseException:
        os.rename(old / final.name, final)  # the old output goes back where it was
        old.rmdir()
        raise
    shutil.rmtree(old)


def _move_in(tmp: Path, final: Path, given: Path) -> None:
    """``tmp`` becomes ``final`` (absent or empty); one made meanwhile by another process is kept."""
    try:
        if final.is_dir():
            final.rmdir()  # empty: nothing is lost
        os.rename(tmp, final)
    except OSError as exc:
        if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR, errno.EISDIR):
            raise
        # Another process (a second run for the same output) finished it meanwhile.
        raise OutputPathError(f"{given}: written by another process while this one ran; that output is "
                              "kept and this one's discarded") from None


@contextmanager
def output_directory(
    path: str | os.PathLike[str], *, force: bool = False, inputs: Iterable[str | os.PathLike[str]] = ()
) -> Iterator[Path]:
    """Yield a new empty directory that becomes ``path`` when the block succeeds.

    Raises :class:`~rls_uncertainty.errors.OutputPathError` before anything is written when
    ``path`` is an existing file, a symbolic link, an existing non-empty directory (allowed
    with ``force``: it is replaced, after the new output is complete; should that final swap
    fail, the old directory is put back), or is, contains or lies inside one of ``inputs``
    (never allowed).
    """
    given = Path(path)
    if given.is_symlink():
        # Resolving it would put the output wherever the link points (even where it dangles).
        raise OutputPathError(
            f"{given}: is a symbolic link (to {os.readlink(given)}); give the directory itself"
        )
    # (os.path.realpath: a symbolic link loop on the way is left as it is, never an exception.)
    final = Path(os.path.realpath(given))
    if final == final.parent:
        raise OutputPathError(f"{given}: cannot write an output over the file system root")
    for item in inputs:
        source = Path(os.path.realpath(item))
        if _inside(final, source) or _inside(source, final):
            raise OutputPathError(
                f"{given}: the output would overwrite the input {item} (it is, contains or lies inside it)"
            )
    replace = False
    if final.exists() and not final.is_dir():
        raise OutputPathError(f"{given}: exists and is not a directory; choose another output directory")
    if final.is_dir() and any(final.iterdir()):
        if not force:
            raise OutputPathError(
                f"{given}: output directory exists and is not empty (use --force to replace it)"
            )
        replace = True
    created_parent = _first_missing_ancestor(final.parent)
    tmp, lock = None, None
    try:
        final.parent.mkdir(parents=True, exist_ok=True)
        for stale in stale_partials(final):
            shutil.rmtree(stale, ignore_errors=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".partial", dir=final.parent))
        lock = _lock_directory(tmp)  # held until the end: the directory is not stale (stale_partials)
        # mkdtemp's private 0700 would reach the output: give it what mkdir would.
        os.chmod(tmp, 0o777 & ~_umask())
        yield tmp
        (_replace_with if replace else _move_in)(tmp, final, given)
    except BaseException:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        if created_parent is not None:
            with suppress(OSError):
                # Only directories this call made, and only while they are empty.
                for p in (final.parent, *final.parent.parents):
                    p.rmdir()
                    if p == created_parent:
                        break
        raise
    finally:
        if lock is not None:
            os.close(lock)
    _fsync_directory(final.parent)


class OutputWriter(ABC):
    """A writer of an output, used in a ``with`` block: :meth:`close` completes the output when
    the block ends normally, :meth:`abort` discards what was written when it raises (the
    exception goes on)."""

    @abstractmethod
    def close(self) -> object:
        """Complete the output."""

    @abstractmethod
    def abort(self) -> None:
        """Discard the unfinished output."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
