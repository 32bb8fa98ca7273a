"""Where outputs go and how each is written. Checked before the work: never onto an input, only
into a folder that can be written. A file is written under a temporary name beside it and
renamed when complete (``atomic_output``, which every writer uses), so that an error, Ctrl-C or
a cancel leaves the previous file (or none), never a truncated one; a run's output folder is
replaced as a whole (``staged_folder``), so that an interrupt leaves the old set of files or the
new one, never a mix. Here too: an input's existence check (``require_file``) and JSON
(``write_json``), the one format with no module of its own.

FloodMesh's own temporary names (``temp_name``, ``staged_folder``) carry the writing process's
id, so that the leftovers of a killed run are known as such and removed by the next one.
"""
from __future__ import annotations

import contextlib
import ctypes
import json
import os
import re
import shutil
import stat
import tempfile
import uuid
from pathlib import Path

import numpy as np

from ..errors import FloodMeshError

# ``.{stem}.{pid}-{hex}.partial{suffix}`` (a file being written) and its SQLite companions;
# the pid-less form is what FloodMesh 0.1 wrote
_TEMP_FILE = re.compile(r"^\..*\.(?:(?P<pid>\d+)-)?[0-9a-f]{8}\.partial(?:\.[^.]*)?"
                        r"(?:-journal|-wal|-shm)?$")
# ``.{folder}.floodmesh-{pid}-{hex}.{staging|old}``: a run's folder being written, or the
# previous one on its way out
_TEMP_FOLDER = re.compile(r"^\.(?P<name>.+)\.floodmesh-(?P<pid>\d+)-[0-9a-f]{8}\."
                          r"(?P<kind>staging|old)$")


# ---------------------------------------------------------------------------------------------
# inputs and outputs
def _identity(path):
    """(real path, (st_dev, st_ino) or None) of a path, following links."""
    real = os.path.realpath(path)
    try:
        st = os.stat(real)
        return real, (st.st_dev, st.st_ino)
    except OSError:
        return real, None


def vector_path(source) -> Path:
    """The file of a vector source: ``file.gpkg`` or, as QGIS writes a layer's source,
    ``file.gpkg|layername=NAME``."""
    return Path(str(source).split("|", 1)[0])


def same_file(a, b) -> bool:
    """Whether two paths name one file, however spelled: relative, through a symbolic link, or
    a hard link of it."""
    real_a, id_a = _identity(a)
    real_b, id_b = _identity(b)
    return real_a == real_b or (id_a is not None and id_a == id_b)


def check_outputs(inputs, outputs) -> None:
    """Refuse, before any work, an output that is (or would replace) one of the inputs, an
    output that is a folder, and an output whose folder (or the nearest existing folder above a
    missing one) cannot be written.

    ``inputs``: paths (None entries are skipped); ``outputs``: file paths to be written.
    """
    inputs = [str(vector_path(p)) for p in inputs if p]
    folders = set()
    for out in outputs:
        if not out:
            continue
        out = Path(out)
        for source in inputs:
            if same_file(out, source):
                raise FloodMeshError(
                    f"the output {out} is the input {source}: FloodMesh never overwrites an "
                    "input; give the output another name or folder")
        if out.is_dir():
            raise FloodMeshError(f"the output {out} is a folder: give a file name")
        folders.add(out.parent)
    for folder in sorted(folders):
        check_writable(_existing_ancestor(folder))  # a missing folder is made when writing


def check_writable(folder) -> None:
    """Refuse a folder that does not exist, is not a folder or cannot be written to (tried by
    creating and removing a hidden file, as read-only mounts and ACLs escape ``os.access``)."""
    folder = Path(folder)
    if not folder.exists():
        raise FloodMeshError(f"output folder {folder} does not exist: create it first")
    if not folder.is_dir():
        raise FloodMeshError(f"{folder} is a file, not a folder: give a folder for the outputs")
    try:
        fd, probe = tempfile.mkstemp(prefix=".floodmesh-probe-", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise FloodMeshError(f"cannot write to the output folder {folder} ({exc.strerror}): "
                             "give a folder you can write to") from None


def check_output_folder(out, inputs, names) -> None:
    """Refuse, before any work, an output folder ``out`` that is a file, lies in a folder
    that cannot be written, or whose outputs ``names`` would replace one of ``inputs``."""
    out = Path(out)
    for source in (str(p) for p in inputs if p):
        if same_file(out, source):
            raise FloodMeshError(f"the output folder {out} is the input {source}: give a "
                                 "folder for the outputs")
    if out.exists() and not out.is_dir():
        raise FloodMeshError(f"{out} is a file, not a folder: give a folder for the outputs "
                             "(it is created if missing)")
    parent = _existing_ancestor(out)
    if parent == Path(os.path.abspath(out)):
        check_outputs(inputs, [out / name for name in names])
    else:
        check_writable(parent)


def _existing_ancestor(path: Path) -> Path:
    path = Path(os.path.abspath(path))
    while not path.exists():
        path = path.parent
    return path


def require_suffix(path, suffixes, what: str) -> None:
    """Refuse an output name whose extension is not one of ``suffixes`` (the format written)."""
    suffix = Path(path).suffix.lower()
    if suffix not in suffixes:
        raise FloodMeshError(f"{Path(path).name}: this writes {what}, but the name ends in "
                             f"{suffix or '(no extension)'!r}: give a name ending in "
                             f"{' or '.join(suffixes)}")


def require_file(path, what: str) -> Path:
    path = Path(path)
    if not path.exists():
        raise FloodMeshError(f"{what} {path} does not exist: check the path")
    if not path.is_file():
        raise FloodMeshError(f"{what} {path} is not a file")
    return path


# ---------------------------------------------------------------------------------------------
# temporary names and their leftovers
def temp_name(path) -> Path:
    """A hidden temporary name beside ``path`` that names this process."""
    path = Path(path)
    return path.with_name(f".{path.stem}.{os.getpid()}-{uuid.uuid4().hex[:8]}.partial"
                          f"{path.suffix}")


def process_gone(pid: str | None) -> bool:
    """Whether the process ``pid`` has ended (None: a name from before pids were recorded)."""
    if pid is None:
        return True
    pid = int(pid)
    if pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    return False


def scratch_folder(kind: str) -> tempfile.TemporaryDirectory:
    """A scratch folder ``floodmesh-KIND-PID-…`` in the system's temporary folder, removed when
    the returned TemporaryDirectory is cleaned up (a ``with`` block's end, an error, Ctrl-C,
    SIGTERM); scratch folders that killed runs left are removed first
    (``remove_stale_scratch``)."""
    remove_stale_scratch()
    return tempfile.TemporaryDirectory(prefix=f"floodmesh-{kind}-{os.getpid()}-")


def remove_stale_scratch() -> None:
    """Remove the scratch folders (``scratch_folder``) that killed runs left in the system's
    temporary folder: those whose process has ended."""
    for path in Path(tempfile.gettempdir()).glob("floodmesh-*-*-*"):
        match = re.fullmatch(r"floodmesh-(bands|tiles|dask)-(?P<pid>\d+)-.*", path.name)
        if match and path.is_dir() and not path.is_symlink() and process_gone(match["pid"]):
            shutil.rmtree(path, ignore_errors=True)


def remove_stale_temporaries(folder) -> list[str]:
    """Remove FloodMesh's own temporary files in ``folder`` left by processes that have ended
    (killed mid-write); return their names. Nothing else is touched."""
    removed = []
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            match = _TEMP_FILE.match(entry.name)
            if match and entry.is_file(follow_symlinks=False) and process_gone(match["pid"]):
                with contextlib.suppress(OSError):
                    os.unlink(entry.path)
                    removed.append(entry.name)
    return removed


_ACTIVE: set = set()  # staging folders this process is writing now (QGIS runs several)


def _clean_run_leftovers(out: Path) -> None:
    """Staging and old folders of ``out`` left by a killed run: staging folders go; an old
    folder comes back when the kill fell between moving it aside and moving the new one in."""
    entries = []
    for folder in (out.parent, out):  # staging beside the folder, or inside it
        with contextlib.suppress(OSError):
            entries += list(os.scandir(folder))
    with contextlib.suppress(OSError):
        for entry in entries:
            match = _TEMP_FOLDER.match(entry.name)
            if not (match and match["name"] == out.name and entry.is_dir(follow_symlinks=False)
                    and (process_gone(match["pid"]) or int(match["pid"]) == os.getpid())
                    and os.path.abspath(entry.path) not in _ACTIVE):
                continue
            if match["kind"] == "old" and not out.exists():
                os.rename(entry.path, out)
            else:
                shutil.rmtree(entry.path, ignore_errors=True)
    if out.is_dir():
        remove_stale_temporaries(out)


# ---------------------------------------------------------------------------------------------
# a file, written atomically
@contextlib.contextmanager
def atomic_output(path):
    """Yield a temporary path beside ``path`` (making its folder if missing); move it into
    place only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path.parent)  # of this target and others, from killed runs
    tmp = temp_name(path)
    try:
        yield tmp
        # the previous file goes first: ext4 writes out at once a file renamed over another
        # (auto_da_alloc), 0.05 s for a 144 MB raster; a new name leaves it to the kernel's
        # write-back, as for any new file
        with contextlib.suppress(FileNotFoundError):
            if not path.is_dir():
                path.unlink()
        # GDAL's sidecar of the previous file (statistics QGIS or gdalinfo -stats wrote) would
        # describe the new one
        with contextlib.suppress(FileNotFoundError):
            Path(f"{path}.aux.xml").unlink()
        os.replace(tmp, path)
    finally:
        for leftover in (tmp, Path(f"{tmp}-journal"), Path(f"{tmp}-wal"), Path(f"{tmp}-shm")):
            with contextlib.suppress(FileNotFoundError):
                leftover.unlink()


# ---------------------------------------------------------------------------------------------
# a run's folder, replaced as a whole
_RENAME_EXCHANGE = 2


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths in one step (Linux renameat2 RENAME_EXCHANGE); False where unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd = -100
    # any failure (EINVAL: a file system without it, ENOSYS: an old kernel) leaves both as
    # they were: the caller then renames in two steps
    return renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE) == 0


def _swap_possible(out: Path, own) -> bool:
    """Whether ``out`` can be replaced as a whole: it is no mount point, holds no folder of the
    user's (folders cannot be hard-linked), is not the working folder (nor above it), and its
    parent can be written."""
    if not out.exists():
        return os.access(out.parent, os.W_OK)
    cwd = os.path.realpath(os.getcwd())
    real = os.path.realpath(out)
    if out.is_symlink() or os.path.ismount(real) or (cwd + os.sep).startswith(real + os.sep):
        return False
    for entry in os.scandir(out):
        if entry.is_dir(follow_symlinks=False) and not own(entry.name):
            return False
    try:
        check_writable(out.parent)
    except FloodMeshError:
        return False
    return True


@contextlib.contextmanager
def staged_folder(out, own=(), keep=()):
    """Yield a hidden staging folder for a run's outputs; when the block succeeds, ``out``
    becomes that folder in one step, else it stays as it was.

    ``own``: names (or a test of a name) of files FloodMesh writes into such a folder (left
    out of the new one when this run did not write them again, so that the folder holds one
    run); other files of ``out``, and the inputs ``keep`` inside it, are carried into the new
    folder as hard links. The new folder takes the old one's owner, group and permissions;
    where it cannot (``_made_like``) or ``out`` cannot be swapped as a whole
    (``_swap_possible``), the staging folder lies inside ``out`` and its files replace the old
    ones one by one. Leftovers of a killed earlier run (``_clean_run_leftovers``) are removed
    first.
    """
    out = Path(os.path.abspath(out))
    _clean_run_leftovers(out)
    own = own if callable(own) else set(own).__contains__
    keep = {os.path.realpath(p) for p in keep if p}
    tag = f"floodmesh-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    swap = _swap_possible(out, own)
    if not swap:
        out.mkdir(parents=True, exist_ok=True)
    staging = (out.parent if swap else out) / f".{out.name}.{tag}.staging"
    try:  # an interrupt as soon as it is made removes it too
        staging.mkdir(parents=True)
        _ACTIVE.add(str(staging))
        if swap and out.exists() and not _made_like(staging, out):
            os.rmdir(staging)
            _ACTIVE.discard(str(staging))
            swap, staging = False, out / staging.name
            staging.mkdir()
            _ACTIVE.add(str(staging))
        yield staging
        if swap:
            _swap_in(out, staging, own, keep, tag)
        else:
            _replace_in(out, staging, own, keep)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        _ACTIVE.discard(str(staging))


def _made_like(new: Path, old: Path) -> bool:
    """Give the folder ``new`` the owner, group and permissions (setgid and sticky bits too) of
    ``old``, which it is to replace, so that a private or a group's folder stays so; False where
    it cannot have them (another user's folder, a group this user is not in) or ``old`` has
    access control lists."""
    try:
        acl = any(name.startswith("system.posix_acl") for name in os.listxattr(old))
    except OSError:  # a file system without extended attributes
        acl = False
    if acl:
        return False
    was = os.stat(old)
    try:
        os.chown(new, was.st_uid, was.st_gid)
        os.chmod(new, stat.S_IMODE(was.st_mode))
        now = os.stat(new)
    except OSError:
        return False
    return (now.st_uid, now.st_gid, now.st_mode) == (was.st_uid, was.st_gid, was.st_mode)


def _carried(out: Path, new: set, own, keep: set) -> list:
    """Entries of the old ``out`` that belong in the new one: the user's files and inputs."""
    if not out.is_dir():
        return []
    return [entry for entry in os.scandir(out) if entry.name not in new
            and (not own(entry.name) or os.path.realpath(entry.path) in keep)
            and not _TEMP_FILE.match(entry.name) and not _TEMP_FOLDER.match(entry.name)
            and not entry.name.startswith(".floodmesh-")]


def _swap_in(out: Path, staging: Path, own, keep: set, tag: str) -> None:
    new = set(os.listdir(staging))
    try:
        for entry in _carried(out, new, own, keep):
            os.link(entry.path, staging / entry.name, follow_symlinks=False)
    except OSError:  # a file system without hard links: replace file by file instead
        for name in set(os.listdir(staging)) - new:
            os.unlink(staging / name)
        _replace_in(out, staging, own, keep)
        return
    if not out.exists():
        os.rename(staging, out)
        return
    old = out.parent / f".{out.name}.{tag}.old"
    if _exchange(staging, out):
        shutil.rmtree(staging, ignore_errors=True)  # now the old folder
        return
    os.rename(out, old)       # a kill between these two renames is undone by the next run
    os.rename(staging, out)
    shutil.rmtree(old, ignore_errors=True)


def _replace_in(out: Path, staging: Path, own, keep: set) -> None:
    new = set(os.listdir(staging))
    for name in sorted(new):
        os.replace(staging / name, out / name)
    for entry in os.scandir(out):
        if (own(entry.name) and entry.name not in new and entry.is_file()
                and os.path.realpath(entry.path) not in keep):
            os.unlink(entry.path)


# ---------------------------------------------------------------------------------------------
# JSON
def jsonable(value):
    """``value`` with numpy numbers as Python ones and non-finite floats as None (null)."""
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, (np.floating, float)):
        return None if not np.isfinite(value) else float(value)
    return value


def write_json(path, data: dict) -> None:
    """Write ``data`` as indented JSON (see ``jsonable``), atomically."""
    with atomic_output(path) as tmp:
        with open(tmp, "w") as fh:
            json.dump(jsonable(data), fh, indent=2, sort_keys=False)
            fh.write("\n")
