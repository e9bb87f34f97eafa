"""One batch run per output folder: an exclusive ``flock`` on a lock file in each folder.

A second run writing into the same folders would delete the first run's temporary files (it
takes them for leftovers of a killed run, :func:`draaw_mi.batch.runner.remove_temp_files`), so the
first run's atomic renames fail, and both would render the same frames. :func:`output_locks`
makes the second run stop before it touches anything, with one line that names the folder and
the process holding it. The kernel releases a ``flock`` when its process ends, however it
ends (kill -9 included), so a lock never outlives its run; a run that ends normally also
deletes its lock file, and the file a killed run leaves behind is simply locked afresh (a run
that locked a file its finishing holder had just deleted locks the folder's new one).

>>> import tempfile
>>> d = tempfile.mkdtemp()
>>> with output_locks([d], "example.toml"):
...     try:
...         with output_locks([d], "other.toml"):
...             pass
...     except BusyError as e:
...         print(str(e).split(";")[0].endswith("is in use by another draaw-mi batch run (pid %d)" % os.getpid()))
True
"""
from __future__ import annotations

import contextlib
import os

from ..errors import BusyError

LOCK_NAME = ".draaw-batch.lock"

try:                                    # POSIX; elsewhere runs are not locked
    import fcntl
except ImportError:                     # pragma: no cover - Windows
    fcntl = None


def _written_pid(fd: int) -> int | None:
    """The pid a run wrote into the lock file open as ``fd``, or None."""
    try:
        text = os.pread(fd, 32, 0).decode(errors="replace").strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _holder(fd: int) -> str:
    pid = _written_pid(fd)
    return "" if pid is None else f" (pid {pid})"


def running_pid(folder: str) -> int | None:
    """The pid of the run holding ``folder``'s lock, or None when no run holds it; the lock is
    not touched (a second process trying it, even for an instant, would make a run starting
    then refuse the folder). The pid is the one the holder wrote into its lock file; a file
    left by a killed run names a process that is gone (or, on Linux, holds no lock on it:
    ``/proc/locks`` lists the files locked and by whom, so a reused pid is not taken for a
    run). A holder that could not write its pid (another user's lock file) is not seen."""
    path = os.path.join(folder, LOCK_NAME)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    except OSError:
        return None
    try:
        pid = _written_pid(fd)
        inode = os.fstat(fd).st_ino
    except OSError:
        return None
    finally:
        os.close(fd)
    if pid is None:
        return None
    locked = _flock_holders(inode)
    if locked is not None:
        return pid if locked else None
    try:
        os.kill(pid, 0)
    except PermissionError:          # alive, another user's
        return pid
    except (OSError, OverflowError):
        return None
    return pid


def _flock_holders(inode: int) -> bool | None:
    """Whether ``/proc/locks`` lists a ``flock`` on a file of this inode number (the device is
    left out: its numbering there is the kernel's); None where there is no such file."""
    try:
        with open("/proc/locks", encoding="ascii", errors="replace") as fh:
            lines = fh.read().splitlines()
    except OSError:
        return None
    for line in lines:
        fields = line.split()
        # "1: FLOCK  ADVISORY  WRITE 1234 08:02:5678 0 EOF" (a waiting lock has "->" after "1:")
        if "FLOCK" in fields and len(fields) >= 6:
            where = fields[fields.index("FLOCK") + 4]
            if where.rsplit(":", 1)[-1] == str(inode):
                return True
    return False


@contextlib.contextmanager
def output_locks(folders, where: str, optional=()):
    """Hold an exclusive lock on every folder in ``folders`` for the duration of the block.

    Raises :class:`~draaw_mi.errors.BusyError` (nothing locked, nothing written) if another
    process holds one of them (another user's lock file is locked through a read-only
    descriptor), or a lock file cannot be opened at all. ``optional``: folders this run only
    reads (its frames there are done) and would clean of a killed run's temporary files;
    where no lock file can be made (a read-only archive), they are skipped, since no run can
    write there either. ``where``: the manifest, for the message. The folders must exist.
    """
    held = []
    optional = set(optional) - set(folders)
    try:
        for folder in sorted(set(folders) | optional):
            if fcntl is None:
                break
            path = os.path.join(folder, LOCK_NAME)
            for _ in range(_ATTEMPTS):
                fd = _lock_file(folder, path, where, folder in optional)
                if fd != _DELETED:
                    break
            else:                       # runs finishing under this one, again and again
                raise BusyError(f"{where}: output folder {folder!r} is in use by another draaw-mi batch "
                                f"run (its lock file was replaced {_ATTEMPTS} times while this run "
                                "locked it); wait for it to finish or choose another --out")
            if fd is None:
                continue                # an optional folder without a lock file
            try:
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
            except OSError:
                pass                    # a read-only descriptor: the lock holds, without our pid
            held.append((fd, path))
        yield
    finally:
        for fd, path in held:
            try:
                os.unlink(path)         # still locked: nobody can hold this file meanwhile
            except OSError:
                pass
            os.close(fd)                # closing the descriptor releases its lock


# A finishing holder deletes its lock file: a run that opened that file just before gets a
# lock on a deleted file and opens the folder's lock file afresh, a few times at most
_ATTEMPTS = 4
_DELETED = -1


def _lock_file(folder: str, path: str, where: str, optional: bool):
    """An open descriptor of ``path`` holding its exclusive lock; ``None`` for an ``optional``
    folder where no lock file can be made; ``_DELETED`` where the lock was got on a file
    its holder deleted meanwhile (try again)."""
    # O_NOFOLLOW: a lock file that is a symbolic link (planted in a shared output folder) would
    # have the run empty and rewrite whatever it points to
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
    except PermissionError:
        # another user's lock file (0644): a read-only descriptor locks it just as well
        # (flock does not care how the file was opened); its holder, if alive, still
        # makes the flock below fail
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
        except OSError as e:
            if optional:
                return None
            raise BusyError(f"{where}: output folder {folder!r} cannot be locked: "
                            f"{path!r} ({e.strerror or e})") from None
    except OSError as e:
        if optional:
            return None
        raise BusyError(f"{where}: output folder {folder!r} cannot be locked: {path!r} "
                        f"({e.strerror or e})") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = _holder(fd)
        os.close(fd)
        raise BusyError(f"{where}: output folder {folder!r} is in use by another draaw-mi "
                        f"batch run{holder}; wait for it to finish or choose another --out") from None
    # the holder we waited on may have deleted the file as it finished: a lock on that
    # unlinked file would not exclude the next run, which creates a new one
    if not _same_file(fd, path):
        os.close(fd)
        return _DELETED
    return fd


def _same_file(fd: int, path: str) -> bool:
    try:
        a, b = os.fstat(fd), os.stat(path)
    except OSError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)
