"""Writing outputs without losing data (rls_uncertainty/files.py): output directories that
appear only when complete and never replace an input, atomic single files, the temporaries an
interrupted write leaves, and the lock beside a file."""

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from bag_samples import no_hang
from bag_samples import tree as _tree

from rls_uncertainty import files
from rls_uncertainty.errors import OutputPathError
from rls_uncertainty.files import FileLock, atomic_file, output_directory, temporaries


def _write(out: Path, name="result.txt", data=b"new"):
    (out / name).write_bytes(data)


@pytest.fixture
def bag(tmp_path):
    """An input bag directory, as the commands take it."""
    bag = tmp_path / "data" / "bag"
    bag.mkdir(parents=True)
    (bag / "bag.mcap").write_bytes(b"recorded flight data")
    (bag / "metadata.yaml").write_bytes(b"rosbag2_bagfile_information: {}\n")
    return bag


# ----------------------------------------------------------------------- output_directory
def test_the_output_appears_only_when_complete(tmp_path):
    out = tmp_path / "out"
    with output_directory(out) as tmp:
        _write(tmp)
        assert not out.exists()
        assert tmp.parent == tmp_path
    assert _tree(tmp_path) == {"out": "dir", "out/result.txt": b"new"}


def test_an_empty_existing_directory_is_used(tmp_path):
    (tmp_path / "out").mkdir()
    with output_directory(tmp_path / "out") as tmp:
        _write(tmp)
    assert _tree(tmp_path) == {"out": "dir", "out/result.txt": b"new"}


def test_a_non_empty_output_is_refused_without_force_and_replaced_with_force(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.txt").write_bytes(b"old")
    (out / "sub").mkdir()
    (out / "sub" / "deep.txt").write_bytes(b"deep")
    before = _tree(tmp_path)
    with pytest.raises(OutputPathError, match=r"not empty.*--force"), output_directory(out) as tmp:
        pytest.fail(f"the block ran with {tmp}")
    assert _tree(tmp_path) == before
    with output_directory(out, force=True) as tmp:
        _write(tmp)
        # The old output stays in place until the new one is complete.
        assert _tree(out) == {"old.txt": b"old", "sub": "dir", "sub/deep.txt": b"deep"}
    assert _tree(tmp_path) == {"out": "dir", "out/result.txt": b"new"}


@pytest.mark.parametrize("case", [
    "output is the input",
    "output inside the input",
    "input inside the output",
    "DIR/sub/.. holding the input",
    "DIR/missing/.. holding the input",
    "output is a symlink to the input",
    "input given through a symlink",
    "output inside a symlink to the input",
])
@pytest.mark.parametrize("force", [False, True])
def test_an_input_is_never_removed_or_overwritten(tmp_path, bag, case, force):
    data = tmp_path / "data"
    (data / "sub").mkdir()
    link = tmp_path / "link"
    link.symlink_to(bag, target_is_directory=True)
    inputs, out = (bag,), {
        "output is the input": bag,
        "output inside the input": bag / "estimates",
        "input inside the output": data,
        "DIR/sub/.. holding the input": data / "sub" / "..",
        "DIR/missing/.. holding the input": data / "missing" / "..",
        "output is a symlink to the input": link,
        "input given through a symlink": bag,
        "output inside a symlink to the input": link / "estimates",
    }[case]
    if case == "input given through a symlink":
        inputs = (link,)
    before = _tree(tmp_path)
    with pytest.raises(OutputPathError, match="input"), output_directory(out, force=force, inputs=inputs) as tmp:
        _write(tmp)
    assert _tree(tmp_path) == before


def test_a_mapping_file_inside_the_output_is_an_input_too(tmp_path, bag):
    mapping = tmp_path / "out" / "mapping.yaml"
    mapping.parent.mkdir()
    mapping.write_bytes(b"imu: {topic: /imu}\n")
    before = _tree(tmp_path)
    with (
        pytest.raises(OutputPathError, match=r"mapping\.yaml"),
        output_directory(tmp_path / "out", force=True, inputs=(bag, mapping)),
    ):
        pass
    assert _tree(tmp_path) == before


@pytest.mark.parametrize("force", [False, True])
def test_an_existing_file_is_refused_and_nothing_is_left_behind(tmp_path, force):
    (tmp_path / "out").write_bytes(b"precious")
    before = _tree(tmp_path)
    with pytest.raises(OutputPathError, match="not a directory"), output_directory(tmp_path / "out", force=force):
        pass
    assert _tree(tmp_path) == before


@pytest.mark.parametrize("force", [False, True])
def test_a_symlink_as_output_is_refused_and_nothing_is_written_where_it_points(tmp_path, force):
    """A dangling link would otherwise make the output appear wherever it points."""
    (tmp_path / "out").symlink_to(tmp_path / "elsewhere" / "target")
    before = _tree(tmp_path)
    with pytest.raises(OutputPathError, match="symbolic link"), output_directory(tmp_path / "out", force=force) as tmp:
        _write(tmp)
    assert _tree(tmp_path) == before


def test_a_failure_removes_what_the_call_created_and_nothing_else(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "keep.txt").write_bytes(b"keep")
    before = _tree(tmp_path)
    # Three parent directories are created for the output; the failure removes them all.
    with pytest.raises(KeyError), output_directory(tmp_path / "a" / "b" / "c" / "d" / "out") as tmp:
        assert (tmp_path / "a" / "b" / "c" / "d").is_dir()
        _write(tmp)
        (tmp / "nested").mkdir()
        _write(tmp / "nested")
        raise KeyError("boom")
    assert _tree(tmp_path) == before


@pytest.mark.parametrize("other", ["directory", "file"])
def test_an_output_another_process_finished_meanwhile_is_kept_and_this_one_discarded(tmp_path, other):
    # Two runs for the same --out: both start while it is absent; the second to finish must not
    # fail with a bare OS error nor touch the first one's output.
    out = tmp_path / "out"
    with pytest.raises(OutputPathError, match="written by another process while this one ran"), \
            output_directory(out) as tmp:
        (tmp / "mine.txt").write_text("second")
        if other == "directory":
            out.mkdir()
            (out / "theirs.txt").write_text("first")
        else:
            out.write_text("first")
    kept = out / "theirs.txt" if other == "directory" else out
    assert kept.read_text() == "first"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_failure_to_create_the_temporary_directory_removes_the_created_parents(tmp_path, monkeypatch):
    def failing_mkdtemp(**kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(files.tempfile, "mkdtemp", failing_mkdtemp)
    with pytest.raises(OSError, match="No space"), output_directory(tmp_path / "a" / "b" / "out"):
        pytest.fail("the block ran")
    assert _tree(tmp_path) == {}


def test_a_failure_leaves_a_replaced_output_as_it_was(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.txt").write_bytes(b"old")
    before = _tree(tmp_path)
    with pytest.raises(RuntimeError), output_directory(out, force=True) as tmp:
        _write(tmp)
        raise RuntimeError("interrupted")
    assert _tree(tmp_path) == before


@pytest.mark.parametrize("step", ["old output moving aside", "new output moving into place"])
def test_a_failure_while_swapping_in_a_forced_output_restores_the_old_one(tmp_path, monkeypatch, step):
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.txt").write_bytes(b"old")
    before = _tree(tmp_path)
    rename = os.rename

    def failing_rename(src, dst):
        moving = Path(src).name.endswith(".partial") if "new" in step else Path(dst).parent.name.endswith(".old")
        if moving:
            raise OSError(28, "No space left on device")
        rename(src, dst)

    monkeypatch.setattr(files.os, "rename", failing_rename)
    with pytest.raises(OSError, match="No space"), output_directory(out, force=True) as tmp:
        _write(tmp)
    assert _tree(tmp_path) == before


def test_the_temporary_directory_never_reuses_a_planted_name(tmp_path):
    """The temporary directory is created exclusively (mkdtemp), so a directory or link
    planted beside the output is never written into."""
    victim = tmp_path / "victim"
    victim.mkdir()
    for name in ("out.partial", ".out.partial", "out.tmp", ".out.old"):
        (tmp_path / name).symlink_to(victim, target_is_directory=True)
    with output_directory(tmp_path / "out") as tmp:
        assert not tmp.is_symlink() and tmp.resolve().parent == tmp_path
        _write(tmp)
    assert list(victim.iterdir()) == []
    assert (tmp_path / "out" / "result.txt").read_bytes() == b"new"


# ----------------------------------------------------------------------------- atomic_file
def test_atomic_file_replaces_the_content_and_leaves_no_temporary_file(tmp_path):
    path = tmp_path / "STATE.npz"
    path.write_bytes(b"old state")
    with atomic_file(path) as fh:
        fh.write(b"new state")
        assert path.read_bytes() == b"old state"
    assert path.read_bytes() == b"new state"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["STATE.npz"]


def test_atomic_file_never_writes_through_a_planted_symlink(tmp_path, monkeypatch):
    victim = tmp_path / "victim.txt"
    victim.write_bytes(b"victim")
    path = tmp_path / "STATE"
    planted = ["STATE.tmp", ".STATE.tmp", "STATE.npz.tmp", f".STATE.{'0' * 16}.tmp"]
    for name in planted:
        (tmp_path / name).symlink_to(victim)
    # Make the temporary-name generator offer the planted name first, then a fresh one:
    # exclusive creation must skip it rather than open it.
    names = iter(["0" * 16, "1" * 16])
    monkeypatch.setattr(files.secrets, "token_hex", lambda n: next(names))
    with atomic_file(path) as fh:
        fh.write(b"state")
    assert victim.read_bytes() == b"victim"
    assert path.read_bytes() == b"state" and not path.is_symlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["victim.txt", "STATE", *planted])


def test_atomic_file_replaces_a_symlink_at_the_target_instead_of_writing_through_it(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_bytes(b"victim")
    path = tmp_path / "STATE"
    path.symlink_to(victim)
    with atomic_file(path) as fh:
        fh.write(b"state")
    assert victim.read_bytes() == b"victim"
    assert not path.is_symlink() and path.read_bytes() == b"state"


def test_atomic_file_fsyncs_the_file_before_the_rename_and_the_directory_after(tmp_path, monkeypatch):
    events = []
    fsync, replace = os.fsync, os.replace

    def record_fsync(fd):
        st = os.fstat(fd)
        kind = "dir" if os.path.samestat(st, os.stat(tmp_path)) else "file"
        data = b""
        if kind == "file":
            data = os.pread(fd, 100, 0)
        events.append(("fsync", kind, data))
        fsync(fd)

    def record_replace(src, dst):
        events.append(("replace", Path(dst).name, b""))
        replace(src, dst)

    monkeypatch.setattr(files.os, "fsync", record_fsync)
    monkeypatch.setattr(files.os, "replace", record_replace)
    with atomic_file(tmp_path / "STATE") as fh:
        fh.write(b"state")
    assert events == [("fsync", "file", b"state"), ("replace", "STATE", b""), ("fsync", "dir", b"")]


@pytest.mark.parametrize("where", ["in the block", "in fsync"])
def test_a_failed_atomic_write_leaves_the_old_file_and_no_temporary_file(tmp_path, monkeypatch, where):
    path = tmp_path / "STATE"
    path.write_bytes(b"old state")

    def failing_fsync(fd):
        raise OSError(5, "Input/output error")

    if where == "in fsync":
        monkeypatch.setattr(files.os, "fsync", failing_fsync)
    with pytest.raises(OSError if where == "in fsync" else ValueError), atomic_file(path) as fh:
        fh.write(b"half")
        if where == "in the block":
            raise ValueError("the writer failed")
    assert path.read_bytes() == b"old state"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["STATE"]


def test_atomic_file_gives_the_permissions_of_a_normal_write_or_of_the_replaced_file(tmp_path):
    old_mask = os.umask(0o027)
    try:
        with atomic_file(tmp_path / "new.csv") as fh:
            fh.write(b"a")
        (tmp_path / "kept.npz").write_bytes(b"old")
        os.chmod(tmp_path / "kept.npz", 0o604)
        with atomic_file(tmp_path / "kept.npz") as fh:
            fh.write(b"b")
    finally:
        os.umask(old_mask)
    assert oct(os.stat(tmp_path / "new.csv").st_mode & 0o777) == oct(0o640)  # not mkstemp's 0600
    assert oct(os.stat(tmp_path / "kept.npz").st_mode & 0o777) == oct(0o604)


def test_the_output_directory_gets_the_permissions_of_mkdir(tmp_path):
    old_mask = os.umask(0o022)
    try:
        with output_directory(tmp_path / "out") as tmp:
            _write(tmp)
    finally:
        os.umask(old_mask)
    assert oct(os.stat(tmp_path / "out").st_mode & 0o777) == oct(0o755)  # not mkdtemp's 0700


# ----------------------------------------------------------------------- temporaries, lock
def _run(code: str, *args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", code, *args], stdout=subprocess.PIPE, text=True)


_KILLED_WRITE = """
import os, signal, sys
from rls_uncertainty.files import atomic_file
with atomic_file(sys.argv[1]) as fh:
    fh.write(b"half a state")
    fh.flush()
    os.kill(os.getpid(), signal.SIGKILL)
"""


def test_temporaries_are_exactly_what_an_interrupted_write_leaves(tmp_path):
    target = tmp_path / "state.npz"
    for _ in range(2):  # two writes killed in the middle
        assert _run(_KILLED_WRITE, str(target)).wait(60) == -signal.SIGKILL
    left = sorted(p for p in tmp_path.iterdir())
    assert len(left) == 2 and not target.exists()
    others = [".state.npz.tmp", ".state.npz.notours.tmp", f".other.npz.{'a' * 16}.tmp", f"state.npz.{'a' * 16}.tmp",
              f".state.npz.{'A' * 16}.tmp"]
    for name in others:
        (tmp_path / name).write_bytes(b"not ours")
    (tmp_path / f".state.npz.{'b' * 16}.tmp").symlink_to(tmp_path / "elsewhere")
    (tmp_path / f".state.npz.{'c' * 16}.tmp").mkdir()
    (tmp_path / ".state.npz.abcd_123.tmp").write_bytes(b"an older version's (tempfile.mkstemp)")
    assert temporaries(target) == sorted([*left, tmp_path / ".state.npz.abcd_123.tmp"])
    assert temporaries(tmp_path / "missing" / "state.npz") == []


_HOLD = """
import sys, time
from rls_uncertainty.files import FileLock
lock = FileLock(sys.argv[1])
print("held", flush=True)
time.sleep(120)
"""


def test_a_lock_held_by_another_process_is_refused_with_its_pid_and_freed_when_it_dies(tmp_path):
    target = tmp_path / "state.npz"
    holder = _run(_HOLD, str(target))
    try:
        assert holder.stdout.readline() == "held\n"
        with pytest.raises(BlockingIOError) as err:
            FileLock(target)
        assert err.value.filename == str(tmp_path / ".state.npz.lock")
        assert err.value.strerror == f"held by process {holder.pid}"
    finally:
        holder.kill()
        holder.wait(60)
        holder.stdout.close()
    lock = FileLock(target)  # the system freed it with the process; its file stayed
    assert lock.held and (tmp_path / ".state.npz.lock").read_text() == f"{os.getpid()}\n"
    with pytest.raises(BlockingIOError):
        FileLock(target)  # one holder, even within one process
    lock.release()
    lock.release()
    assert not lock.held and sorted(tmp_path.iterdir()) == []


def test_a_lock_removed_by_its_holder_while_another_takes_it_is_taken_again(tmp_path, monkeypatch):
    """The holder removes the lock file as it releases it, between another process's open
    and its flock: the other locks a file no longer at the path, sees that, and locks anew."""
    target = tmp_path / "state.npz"
    first = FileLock(target)
    real_flock = files.fcntl.flock
    calls = []

    def flock(fd, op):
        calls.append(fd)
        if len(calls) == 1:
            first.release()  # the old holder lets go just after our open
        return real_flock(fd, op)

    monkeypatch.setattr(files.fcntl, "flock", flock)
    second = FileLock(target)
    monkeypatch.undo()
    assert len(calls) == 2 and second.held
    with pytest.raises(BlockingIOError):
        FileLock(target)  # the file at the path is the one the second holds
    second.release()


@pytest.mark.parametrize("kind", ["fifo", "symlink", "directory"])
def test_a_lock_path_that_is_not_a_regular_file_is_refused_without_blocking(tmp_path, kind):
    target = tmp_path / "state.npz"
    lock = tmp_path / ".state.npz.lock"
    if kind == "fifo":
        os.mkfifo(lock)
    elif kind == "symlink":
        lock.symlink_to(tmp_path / "elsewhere")
    else:
        lock.mkdir()
    with no_hang(10), pytest.raises(OSError) as err:
        FileLock(target)
    assert not isinstance(err.value, (BlockingIOError, TimeoutError))
    assert not (tmp_path / "elsewhere").exists() and sorted(p.name for p in tmp_path.iterdir()) == [lock.name]


# ----------------------------------------------------------------------- inputs
def test_an_input_that_is_not_a_regular_file_or_directory_is_named_without_being_opened(tmp_path):
    import socket

    (tmp_path / "file").write_bytes(b"data")
    (tmp_path / "dir").mkdir()
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    (tmp_path / "link").symlink_to(tmp_path / "file")
    with socket.socket(socket.AF_UNIX) as sock:
        sock.bind(str(tmp_path / "sock"))
        with no_hang(10):  # a FIFO opened for reading would block: nothing is opened
            found = {name: files.input_problem(tmp_path / name) for name in sorted(os.listdir(tmp_path))}
    assert found == {"dir": None, "file": None, "link": None,
                     "fifo": "a FIFO, not a regular file or a directory",
                     "loop": "a symbolic link loop",
                     "sock": "a socket, not a regular file or a directory"}
    assert files.input_problem("/dev/null") == "a character device, not a regular file or a directory"
    assert files.input_problem(tmp_path / "missing") == "no such file or directory"
    assert files.input_problem(tmp_path / "dir", directory=False) == "a directory, not a regular file"


def test_an_input_that_is_a_symlink_loop_is_compared_without_an_exception(tmp_path):
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    with output_directory(tmp_path / "out", inputs=[tmp_path / "loop"]) as tmp:
        _write(tmp)
    assert (tmp_path / "out" / "result.txt").read_bytes() == b"new"


# ----------------------------------------------------------------------- unfinished outputs
_KILLED_OUTPUT = """
import sys, time
from rls_uncertainty.files import output_directory
with output_directory(sys.argv[1]) as tmp:
    (tmp / "half.csv").write_text("half an output")
    print(tmp, flush=True)
    time.sleep(120)
"""


def _partials(directory: Path) -> list[Path]:
    return sorted(p for p in directory.iterdir() if p.name.endswith(".partial"))


def test_the_unfinished_output_of_a_killed_run_is_removed_by_the_next_run(tmp_path):
    out = tmp_path / "out"
    writer = _run(_KILLED_OUTPUT, str(out))
    try:
        left = Path(writer.stdout.readline().strip())
        assert _partials(tmp_path) == [left]
        assert files.stale_partials(out) == []  # its writer is alive: not stale
    finally:
        writer.kill()
        writer.wait(60)
        writer.stdout.close()
    assert _partials(tmp_path) == [left] and files.stale_partials(out) == [left]
    with output_directory(out) as tmp:
        assert files.stale_partials(out) == [] and _partials(tmp_path) == [tmp]  # its own is locked
        _write(tmp)
    assert _partials(tmp_path) == [] and sorted(os.listdir(out)) == ["result.txt"]


def test_only_unlocked_directories_of_the_output_name_pattern_are_stale(tmp_path):
    out = tmp_path / "out"
    stale = tmp_path / ".out.ab_cd123.partial"
    stale.mkdir()
    others = [".out.abcd123.partial", ".out.ABCD1234.partial", ".other.abcd1234.partial", "out.abcd1234.partial",
              ".out.abcd1234.old"]
    for name in others:
        (tmp_path / name).mkdir()
    (tmp_path / ".out.file1234.partial").write_bytes(b"a file")
    (tmp_path / ".out.link1234.partial").symlink_to(stale)
    assert files.stale_partials(out) == [stale]
    holder = _run(_KILLED_OUTPUT, str(out))  # a live writer's own is never stale, nor removed
    try:
        live = Path(holder.stdout.readline().strip())
        with output_directory(out) as tmp:
            _write(tmp)
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
            [*others, ".out.file1234.partial", ".out.link1234.partial", live.name, "out"])
    finally:
        holder.kill()
        holder.wait(60)
        holder.stdout.close()
