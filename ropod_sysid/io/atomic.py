"""Write output files atomically: to a temporary file beside the target, then rename.

A failure part-way leaves no partial output file behind. A symbolic link is written through
(the link stays, its target gets the content); anything else that is not a regular file (a
device, a FIFO, a directory) is refused, never replaced.

A command that writes several files checks them all first and writes all or none of them:

    with OutputSet([("--out", out), ("--report", report)], inputs=[("LOGS", p) for p in logs]):
        ...                      # every atomic_path() in here is renamed only when the block ends

:class:`OutputSet` refuses, before any work, an output that is one of the inputs (the same
path, a link to it, a hard link), two outputs that are the same file, and an output whose
folder cannot be created or written in; the writers inside the block keep using :func:`atomic_path`.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from types import TracebackType

from ropod_sysid.errors import InputError

PathLike = str | os.PathLike[str]

# the OutputSet whose block is running: atomic_path() hands its renames to it
_ACTIVE: contextvars.ContextVar[OutputSet | None] = contextvars.ContextVar("_ACTIVE",
                                                                           default=None)

_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISSOCK, "a socket"))


def file_kind(mode: int) -> str:
    """What a file of ``os.stat`` mode ``mode`` is, in words ("a FIFO", "a directory" …)."""
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def write_target(path: PathLike, label: str | None = None) -> Path:
    """The file that writing ``path`` replaces: ``path`` with its symbolic links resolved.

    Raises :class:`InputError` if that is something other than a regular file (or nothing).
    ``label`` (e.g. ``--out``) starts the message.
    """
    target = Path(os.path.realpath(path))
    try:
        mode = os.stat(target).st_mode
    except (FileNotFoundError, NotADirectoryError):  # a new file (its folder is checked apart)
        return target
    except OSError as exc:
        raise InputError(f"{_name(label, path)}: cannot use it as an output "
                         f"({exc.strerror or exc})") from None
    if not stat.S_ISREG(mode):
        fix = ("give the file name inside it" if stat.S_ISDIR(mode)
               else "only a regular file is written; give a file name")
        raise InputError(f"{_name(label, path)}: is {file_kind(mode)}; {fix}")
    return target


def _name(label: str | None, path: PathLike) -> str:
    return f"{label} {path}" if label else str(path)


def _publish(tmp: Path, target: Path) -> None:
    """Give ``tmp`` the permissions of a new file and rename it onto ``target``."""
    # mkstemp creates the file private (0600); give it the permissions of a new file
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    os.replace(tmp, target)


@contextlib.contextmanager
def atomic_path(path: PathLike) -> Iterator[Path]:
    """Yield a temporary path beside the file ``path`` names; rename it onto it on success.

    Inside an :class:`OutputSet` block the rename waits for the end of the block.
    """
    target = write_target(path)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({exc.strerror or exc})") from None
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        outputs = _ACTIVE.get()
        if outputs is not None:
            outputs._staged.append((tmp_path, target))
        else:
            _publish(tmp_path, target)
    except OSError as exc:  # e.g. the disk is full
        tmp_path.unlink(missing_ok=True)
        raise InputError(f"{path}: cannot write ({exc.strerror or exc})") from None
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def atomic_write_text(path: PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def atomic_write_bytes(path: PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def same_file(a: PathLike, b: PathLike) -> bool:
    """Whether ``a`` and ``b`` are one file: the same path once resolved, or the same inode."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        sa, sb = os.stat(a), os.stat(b)
    except OSError:
        return False
    return (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino)


def check_outputs(outputs: Iterable[tuple[str, PathLike | None]],
                  inputs: Iterable[tuple[str, PathLike | None]] = ()) -> None:
    """Refuse, with one line naming the option, the path and the fix, an output that

    - is something other than a regular file (a directory, device, FIFO; links are followed),
    - lies in a folder that does not exist or where no file can be created,
    - is one of ``inputs`` (by path, symbolic or hard link), or the same file as another output.

    ``outputs`` and ``inputs`` are (option or argument name, path) pairs; None paths are skipped.
    """
    outs = [(label, path) for label, path in outputs if path is not None]
    ins = [(label, path) for label, path in inputs if path is not None]
    for k, (label, path) in enumerate(outs):
        target = write_target(path, label)
        _check_folder(label, path, target.parent)
        for in_label, in_path in ins:
            if same_file(path, in_path):
                raise InputError(f"{label} {path}: is also the input {in_label} {in_path}; "
                                 "writing it would destroy the input; give another file name")
        for other_label, other in outs[:k]:
            if same_file(path, other):
                raise InputError(f"{other_label} {other} and {label} {path}: are the same "
                                 "file; give each output its own name")


def _check_folder(label: str, path: PathLike, folder: Path) -> None:
    if not folder.is_dir():
        raise InputError(f"{label} {path}: the folder {folder} does not exist; create it or "
                         "give another path")
    try:  # the one sure test of writability: create (and remove) a file there
        fd, probe = tempfile.mkstemp(prefix=".ropod-sysid-probe.", dir=folder)
    except OSError as exc:
        raise InputError(f"{label} {path}: cannot write in {folder} "
                         f"({exc.strerror or exc}); give a writable folder") from None
    os.close(fd)
    os.unlink(probe)


class OutputSet:
    """All or nothing for a command's outputs (see the module docstring).

    On entry: creates the ``folders`` (option name, path) and the outputs' folders that are
    missing, then :func:`check_outputs`. In the block every :func:`atomic_path` writes its
    temporary file; when the block succeeds they are all renamed onto their targets; when it
    fails they are all removed, as are the folders it created.
    """

    def __init__(self, outputs: Iterable[tuple[str, PathLike | None]],
                 inputs: Iterable[tuple[str, PathLike | None]] = (), *,
                 folders: Iterable[tuple[str, PathLike]] = ()) -> None:
        self.outputs = list(outputs)
        self.inputs = list(inputs)
        self.folders = list(folders)
        self._staged: list[tuple[Path, Path]] = []
        self._created: list[Path] = []
        self._token: contextvars.Token[OutputSet | None] | None = None

    def __enter__(self) -> OutputSet:
        try:
            for label, folder in self.folders:
                self._make_folder(label, folder, Path(folder))
            for label, path in self.outputs:
                if path is not None:
                    self._make_folder(label, path, write_target(path, label).parent)
            check_outputs(self.outputs, self.inputs)
        except BaseException:
            self._remove_folders()
            raise
        self._token = _ACTIVE.set(self)
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        assert self._token is not None
        _ACTIVE.reset(self._token)
        staged, self._staged = self._staged, []
        try:
            if exc_type is None:
                while staged:
                    tmp, target = staged[0]
                    try:
                        _publish(tmp, target)
                    except OSError as exc:
                        raise InputError(f"{target}: cannot write ({exc.strerror or exc})"
                                         ) from None
                    staged.pop(0)
        finally:
            for tmp, _ in staged:
                tmp.unlink(missing_ok=True)
            if exc_type is not None:
                self._remove_folders()

    def _make_folder(self, label: str, path: PathLike, folder: Path) -> None:
        """Create ``folder`` (of output ``label path``) if missing, remembering what it made."""
        if folder.exists() and not folder.is_dir():
            what = "exists" if Path(path) == folder else f"its folder {folder} exists"
            raise InputError(f"{label} {path}: {what} and is not a directory; give a "
                             "directory")
        # innermost first; remembered before mkdir, which may make some and then fail
        self._created = [p for p in (folder, *folder.parents) if not p.exists()] + self._created
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"{label} {path}: cannot create the directory {folder} "
                             f"({exc.strerror or exc}); give a writable folder") from None

    def _remove_folders(self) -> None:
        for folder in self._created:
            with contextlib.suppress(OSError):  # not empty: someone else wrote there
                folder.rmdir()
        self._created = []
