"""Output directories and files that are never seen half-written.

A command writes its whole output into a *staging* directory beside the target
(``PARENT/.NAME.staging-PID``) and, once everything is written, swaps it into place:

* on Linux the swap is one ``renameat2(RENAME_EXCHANGE)`` system call, so a reader of
  ``PARENT/NAME`` sees the complete previous set of files or the complete new set, at
  every instant, whatever moment the run is killed;
* elsewhere (or on a file system without it) the old directory is renamed aside and the
  new one renamed into place: two renames, with a window of microseconds in which
  ``NAME`` does not exist; a kill inside it leaves both complete sets beside it.

Rules:

* **One run at a time** per target: a lock file ``PARENT/.NAME.lock`` (``flock``, released
  by the kernel when the process dies, so a killed run never leaves a stale lock); a
  second run stops at once with :class:`OutputError`.
* **Checked before any work**: entering :func:`staged_directory` creates the parent and
  the staging directory and writes a probe file, so a parent that is a file, a read-only
  place or an over-long name fails before an analysis runs, in one line naming the path.
* **Stale files**: the directory holds a manifest ``.overbound.json`` of the files each
  command wrote. Files that an earlier run of the *same* command wrote and this run does
  not (e.g. ``evt-horizontal.json`` when the new input has no HPL) are removed; files of
  other commands and files overbound did not write are carried into the new set
  (hard links, copies where links fail) and listed in :attr:`StagedDirectory.kept`.
* Leftovers of killed runs (staging and old directories) are removed by the next run.

Durability against power loss (``fsync``) is not attempted: the guarantee is against a
killed or failing process.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import glob
import json
import os
import re
import shutil
import signal
import stat
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["MANIFEST", "OutputError", "StagedDirectory", "locked", "staged_directory", "staged_files"]

#: The manifest of an output directory: which command wrote which files.
MANIFEST = ".overbound.json"


class OutputError(OSError):
    """An output path that cannot be written, or a target in use by another run."""

    def __init__(self, path: str | Path, reason: str):
        self.path = str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}")

    def __str__(self) -> str:
        return f"{self.path}: {self.reason}"


@dataclass
class StagedDirectory:
    """The staging directory of one run, with what the commit did.

    Attributes
    ----------
    target : the output directory the user named.
    path : where the run writes (the staging directory) until :meth:`final` maps it back.
    command : the command whose files these are (the manifest's key).
    removed : after the commit, files of an earlier run of ``command`` that this run did
        not write (removed, relative to ``target``).
    kept : after the commit, files carried over from the old directory that ``command`` did
        not write (another command's, or not overbound's).
    """

    target: Path
    path: Path
    command: str
    removed: list[str] = field(default_factory=list)
    kept: list[str] = field(default_factory=list)

    def final(self, path: str | Path) -> Path:
        """Where ``path`` (inside the staging directory) is after the commit."""
        return self.target / Path(path).relative_to(self.path)


def _lock_path(target: Path) -> Path:
    return target.parent / f".{target.name}.lock"


def _checked_parent(target: Path) -> None:
    """Create the parent directories; one-line errors for a file in the way, no permission, a bad name."""
    try:
        for p in target.parents:
            if p.exists() and not p.is_dir():
                raise OutputError(p, "is a file, but a parent of the output must be a directory")
            if p.exists():
                break
        target.parent.mkdir(parents=True, exist_ok=True)
        target.exists()  # an over-long name fails here
    except OutputError:
        raise
    except OSError as exc:
        raise OutputError(target, f"cannot be written ({exc.strerror})") from None


@contextlib.contextmanager
def locked(target: Path) -> Iterator[None]:
    """Hold the target's lock file; raise :class:`OutputError` when another run holds it."""
    path = _lock_path(target)
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise OutputError(target, f"cannot write beside it ({exc.strerror})") from None
        if not _try_lock(fd):
            os.close(fd)
            raise OutputError(target, f"in use by another overbound run (lock {path.name}); wait for it")
        # The file may have been unlinked by the run that held it just before we locked it.
        try:
            same = os.stat(path).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)
        os.close(fd)


def _try_lock(fd: int) -> bool:
    try:
        import fcntl
    except ImportError:  # Windows: msvcrt locks a byte range
        import msvcrt

        try:
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
            return True
        except OSError:
            return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except OSError as exc:
        if exc.errno in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
            return False
        raise


def _leftovers(target: Path, kind: str) -> list[Path]:
    """``.NAME.<kind>-<pid>`` beside ``target`` (exactly: a user's ``.NAME.old-backup`` is not ours)."""
    pattern = re.compile(rf"\.{re.escape(target.name)}\.{kind}-\d+")
    return sorted(
        p for p in target.parent.glob(f".{glob.escape(target.name)}.{kind}-*") if pattern.fullmatch(p.name)
    )


def _remove_leftovers(target: Path) -> None:
    """Staging and old directories of killed runs (we hold the lock: no live run owns them).

    A run killed inside the two-rename swap (systems without an atomic exchange) left the
    previous set aside and no target: it is renamed back first, so nothing of it is lost.
    """
    old = _leftovers(target, "old")
    if old and not os.path.lexists(target):
        os.rename(old.pop(), target)
    for p in [*_leftovers(target, "staging"), *old]:
        _remove(p)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            path.unlink()


def _make_staging(target: Path) -> Path:
    """An empty staging directory beside ``target``, with a probe file written and removed."""
    stage = target.parent / f".{target.name}.staging-{os.getpid()}"
    try:
        stage.mkdir()
        probe = stage / ".probe"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        shutil.rmtree(stage, ignore_errors=True)
        raise OutputError(target, f"cannot write there ({exc.strerror})") from None
    return stage


def _check_directory_target(target: Path) -> None:
    if target.is_dir() and (os.path.ismount(target) or target.stat().st_dev != target.parent.stat().st_dev):
        # a volume cannot be renamed: its directories can
        raise OutputError(target, "is a mount point; give a directory inside it (e.g. -o DIR/out)")
    if target.exists() and not target.is_dir():
        raise OutputError(target, "is a file, but the output must be a directory")
    if target.exists() and not os.access(target, os.W_OK | os.X_OK):
        raise OutputError(target, "is not writable")
    if Path.cwd() == target or target in Path.cwd().parents:
        raise OutputError(target, "is the current directory or holds it; give the output its own directory")


@contextlib.contextmanager
def _terminate_as_interrupt() -> Iterator[None]:
    """SIGTERM raises KeyboardInterrupt (main thread only), so that the staging is cleaned up."""
    if sys.platform == "win32" or not _main_thread():
        yield
        return

    def handler(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def staged_directory(target: str | Path, *, command: str) -> Iterator[StagedDirectory]:
    """Write an output directory through a staging directory, swapped into place at the end.

    Parameters
    ----------
    target : the output directory (created with its parents if missing).
    command : the writing command's name, recorded in the manifest.

    Yields
    ------
    StagedDirectory : write into ``.path``; ``.final(p)`` is where ``p`` ends up. On an
        exception the staging directory is removed and the target is left untouched.

    Raises
    ------
    OutputError
        The target cannot be written, or another run holds it.
    """
    # a symlink to a directory: the directory it points to is the output (the link stays)
    target = Path(os.path.realpath(target))
    _checked_parent(target)
    _check_directory_target(target)
    with locked(target), _terminate_as_interrupt():
        _remove_leftovers(target)
        stage = StagedDirectory(target=target, path=_make_staging(target), command=command)
        try:
            yield stage
            try:
                _commit(stage)
            except OSError as exc:
                raise OutputError(target, f"cannot put the new files in place ({exc})") from None
        finally:
            _remove(stage.path)


def _written(root: Path) -> list[str]:
    return sorted(
        p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file() and p.name != MANIFEST
    )


def _read_manifest(directory: Path) -> dict[str, list[str]]:
    try:
        doc = json.loads((directory / MANIFEST).read_text(encoding="utf-8"))
        return {str(k): [str(f) for f in v] for k, v in doc.get("files", {}).items()}
    except (OSError, ValueError, AttributeError, TypeError):
        return {}


def _commit(stage: StagedDirectory) -> None:
    """Carry over what is not this command's, write the manifest, swap the directories.

    File by file, directories merged: a file of the old set that the new set does not hold
    is carried over (hard link, or copy) unless the manifest lists it as a file of an
    earlier run of this command; then it is a stale file, removed and listed.
    """
    target, new = stage.target, stage.path
    files = {stage.command: _written(new)}
    if target.is_dir():
        old = _read_manifest(target)
        previous = set(old.pop(stage.command, []))
        for rel in _old_entries(target):
            if os.path.lexists(new / rel) and not (new / rel).is_dir():
                continue  # rewritten by this run
            if rel in previous:
                continue  # this command's, not written again: stale
            _carry(target / rel, new / rel)
            stage.kept.append(rel)
        stage.removed = sorted(p for p in previous if p not in files[stage.command])
        for cmd, listed in old.items():
            if kept := [f for f in listed if (new / f).exists() and f not in files[stage.command]]:
                files[cmd] = kept
    doc = {"format": 1, "files": dict(sorted(files.items()))}
    (new / MANIFEST).write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    _swap(new, target)


def _old_entries(directory: Path) -> list[str]:
    """Files, symlinks and empty directories of the old set, relative, except the manifest.

    Symlinked directories are entries, not walked; so are directories on another file
    system (a mount inside the output), carried whole by :func:`_carry`.
    """
    out = []
    for root, dirs, names in os.walk(directory):
        base = Path(root)
        for d in list(dirs):
            p = base / d
            if p.is_symlink() or os.path.ismount(p):
                dirs.remove(d)
                names.append(d)
        rel_root = base.relative_to(directory)
        if not dirs and not names and base != directory:
            out.append(rel_root.as_posix())  # an empty directory: kept as one
        out += [(rel_root / n).as_posix() for n in names if not (base == directory and n == MANIFEST)]
    return sorted(out)


def _carry(src: Path, dst: Path) -> None:
    """Hard-link (or copy) ``src`` into the new set: the old set stays intact until the swap."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    if src.is_dir() and not src.is_symlink():
        shutil.copytree(src, dst, symlinks=True, copy_function=_link_or_copy, dirs_exist_ok=True)
    else:
        _link_or_copy(src, dst)


def _link_or_copy(src: str | Path, dst: str | Path) -> None:
    if Path(src).is_symlink():
        os.symlink(os.readlink(src), dst)
        return
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def _swap(new: Path, target: Path) -> None:
    """Put ``new`` at ``target``; the old directory ends up at ``new``'s path (removed by the caller).

    SIGINT and SIGTERM are held during the swap, so that the two-rename fallback is not cut
    between its renames by a signal (a SIGKILL there is repaired by the next run).
    """
    with _signals_held():
        if not target.exists():
            os.rename(new, target)
            return
        with contextlib.suppress(OSError):
            os.chmod(new, stat.S_IMODE(target.stat().st_mode))
        if _exchange(new, target):
            return
        aside = target.parent / f".{target.name}.old-{os.getpid()}"
        os.rename(target, aside)
        try:
            os.rename(new, target)
        except OSError:
            os.rename(aside, target)
            raise
        os.rename(aside, new)


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    if not hasattr(signal, "pthread_sigmask"):  # Windows
        yield
        return
    held = {signal.SIGINT, signal.SIGTERM}
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _exchange(a: Path, b: Path) -> bool:
    """Atomically exchange two paths (Linux ``renameat2``); False where unsupported."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), str(b))


@contextlib.contextmanager
def staged_files(target: str | Path) -> Iterator[Path]:
    """Write a file, and the files named after it beside it, through a staging directory.

    Yields the path to write ``target`` at (same name, inside the staging directory); the
    files written there are renamed into ``target``'s directory on success, each one
    atomically, ``target`` itself last (so that its presence says the set is complete).
    The lock, the checks and the clean-up are those of :func:`staged_directory`; on an
    exception nothing is moved.
    """
    target = Path(os.path.abspath(target))
    _checked_parent(target)
    if target.is_dir():
        raise OutputError(target, "is a directory, expected a file name")
    if target.exists() and not os.access(target, os.W_OK):
        raise OutputError(target, "is not writable")
    with locked(target), _terminate_as_interrupt():
        _remove_leftovers(target)
        stage = _make_staging(target)
        try:
            yield stage / target.name
            names = sorted(p.name for p in stage.iterdir())
            for name in sorted(names, key=lambda n: n == target.name):
                os.replace(stage / name, target.parent / name)
        finally:
            shutil.rmtree(stage, ignore_errors=True)
