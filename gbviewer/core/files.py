"""Writing output files safely: complete or absent, never a surprise overwrite."""

from __future__ import annotations

import os
import stat
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path

from .errors import GBViewerError
from .outputs import PathLike, refuse_inputs

NAME_MAX = 255  # bytes of one file or folder name (Linux, macOS and Windows file systems)
TEMP_EXTRA = 10  # what atomic_write's temporary name adds to the file's: ".NAME-12345678" ("." "-" 8 letters)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def refuse_overwrite(path: str | Path, force: bool = False) -> Path:
    """Raise the error `atomic_write` would for an existing `path` without `force`: call it before long work that
    ends in writing `path`."""
    path = Path(path)
    if path.exists() and not force:
        raise GBViewerError(f"{path}: exists; pass --force to overwrite")
    return path


def check_name_lengths(path: Path, folder: bool, option: str) -> None:
    """Refuse a folder name over NAME_MAX bytes or a file name over NAME_MAX - TEMP_EXTRA (its temporary file must
    fit too), naming `option` (e.g. '--out') when given."""
    parts = path.parts
    for i, part in enumerate(parts):
        limit = NAME_MAX - (0 if folder or i < len(parts) - 1 else TEMP_EXTRA)
        if len(os.fsencode(part)) > limit:
            what = "folder" if folder or i < len(parts) - 1 else "file"
            raise GBViewerError(
                f"{option + ' ' if option else ''}{part[:40]}...: {what} name of "
                f"{len(os.fsencode(part))} bytes; expected at most {limit}"
            )


def check_writable(
    path: str | Path,
    force: bool = False,
    *,
    folder: bool = False,
    inputs: Iterable[PathLike | None] = (),
    option: str = "",
) -> Path:
    """Raise now the error that writing `path` (a file; with `folder`, a folder to write files into) would raise
    after long work: an existing file without `force`, a folder where a file goes or the reverse, a place that
    cannot be created or may not be written in (probed with a temporary file, so read-only mounts count for root
    too), and, with or without `force`, a file that is one of the command's `inputs` (`refuse_inputs`). Leaves
    nothing behind; call it before the work. `option`: the option that gave `path`, named in a name-length error."""
    path = Path(path)
    check_name_lengths(path, folder, option)
    refuse_inputs([path], inputs)
    if folder and path.exists() and not path.is_dir():
        raise GBViewerError(f"{path}: exists and is not a folder")
    if not folder:
        if path.is_dir():
            raise GBViewerError(f"{path}: is a folder; expected a file name")
        refuse_overwrite(path, force)
    place = path if folder else path.parent
    while not place.exists() and place != place.parent:
        place = place.parent  # the nearest existing folder, in which the rest would be created
    if not place.is_dir():
        raise GBViewerError(f"{path}: cannot create it, {place} is not a folder")
    try:
        fd, probe = tempfile.mkstemp(prefix=".gbviewer-probe-", dir=place)
    except OSError as exc:
        raise GBViewerError(f"{path}: cannot write in {place} ({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(probe)
    return path


def atomic_write(path: str | Path, write: Callable[[Path], object], force: bool = False) -> Path:
    """Call write(tmp) for a temporary file beside `path`, flush it to disk, then move it into place and flush the
    folder, so readers never see a partial file and a crash after the return does not lose it. Without `force` an
    existing file is refused, including one that appears while writing (the final step links rather than renames). The
    file gets the usual umask permissions."""
    path = refuse_overwrite(path, force)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{path.stem}-", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        write(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        if force:
            os.replace(tmp, path)
        else:
            try:
                os.link(tmp, path)  # fails if the file exists by now
            except FileExistsError:
                raise GBViewerError(f"{path}: exists; pass --force to overwrite") from None
            except OSError:  # a file system without hard links
                if path.exists():
                    raise GBViewerError(f"{path}: exists; pass --force to overwrite") from None
                os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    _sync_folder(path.parent)
    return path


def _sync_folder(folder: Path) -> None:
    """Flush a folder's entries to disk (POSIX: fsync of the folder), so that a rename or link into it survives a
    crash; where folders cannot be opened (Windows) or synced (some file systems) the rename stands as it is."""
    if not hasattr(os, "O_DIRECTORY"):
        return
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def file_stat(path: Path) -> tuple[int, int] | None:
    """A regular file's (size, mtime_ns), else None."""
    try:
        st = path.stat()
    except OSError:
        return None
    return (st.st_size, st.st_mtime_ns) if stat.S_ISREG(st.st_mode) else None
