"""Atomic outputs: one file, a set of sibling files, or a whole folder.

Readers never see a half-written output, and a run killed at any point leaves either the
old complete output or the new one:

- one file: written to ``.NAME.PID-TOKEN.tmp`` beside it, fsynced, renamed over it;
- a set of sibling files (a scan's PNG + TIFF + JSON): every member is written to its
  temporary name first, then the *manifest* (the JSON, which lists the SHA-256 of every
  other member), all fsynced; then the members are renamed into place and the manifest
  last. A run killed during the renames leaves a complete manifest among the temporary
  files, and the next run over the same output rolls the set forward
  (:func:`recover`) before it does anything else; :func:`verify_set` tells a reader
  whether the files on disk are the set their manifest names;
- a folder (the report): written into ``.NAME.PID-TOKEN.tmp/`` beside it and exchanged
  with the old folder in one ``renameat2(RENAME_EXCHANGE)`` (Linux), or by two renames
  where that call is missing; the old folder is then deleted.

Temporary names carry the writer's PID: a leftover whose process is gone is stale and is
removed (or rolled forward) by :func:`recover`, which every writer here calls first.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import hashlib
import json
import os
import re
import secrets
import shutil
from collections.abc import Iterator
from pathlib import Path

_TMP = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)-(?P<token>[0-9a-f]{8})\.(?P<kind>tmp|old)$")


def _token() -> str:
    return f"{os.getpid()}-{secrets.token_hex(4)}"


def _tmp_name(path: Path, token: str, kind: str = "tmp") -> Path:
    return path.with_name(f".{path.name}.{token}.{kind}")


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _write_synced(path: Path, data: bytes) -> None:
    umask = os.umask(0)
    os.umask(umask)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666 & ~umask)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _as_bytes(data: str | bytes) -> bytes:
    return data.encode() if isinstance(data, str) else data


def write_atomic(path: str | Path, data: str | bytes) -> Path:
    """Write one file so that readers never see it half-written (missing folders are
    created)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    recover(path.parent, {path.name})
    tmp = _tmp_name(path, _token())
    try:
        _write_synced(tmp, _as_bytes(data))
        os.replace(tmp, path)
        _fsync_dir(path.parent)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_set(members: dict[str | Path, str | bytes], manifest: str | Path, meta: dict) -> Path:
    """Write sibling files and their JSON manifest as one set.

    Parameters
    ----------
    members : path -> content of every file of the set except the manifest (same folder)
    manifest : path of the JSON manifest, written last; it holds ``meta`` and
        ``"files": {name: sha256}`` of the members
    """
    manifest = Path(manifest)
    folder = manifest.parent
    paths = {Path(p): _as_bytes(d) for p, d in members.items()}
    if any(p.parent != folder for p in paths):
        raise ValueError("write_set: every member must lie in the manifest's folder")
    folder.mkdir(parents=True, exist_ok=True)
    recover(folder, {p.name for p in paths} | {manifest.name})
    token = _token()
    files = {p.name: hashlib.sha256(d).hexdigest() for p, d in paths.items()}
    body = json.dumps(meta | {"files": files}, indent=2).encode()
    tmps = [(_tmp_name(p, token), p, d) for p, d in paths.items()]
    tmps.append((_tmp_name(manifest, token), manifest, body))
    try:
        for tmp, _p, data in tmps:
            _write_synced(tmp, data)
        _fsync_dir(folder)
    except BaseException:
        for tmp, _p, _d in tmps:
            tmp.unlink(missing_ok=True)
        raise
    for tmp, p, _d in tmps:  # members first, the manifest last
        os.replace(tmp, p)
    _fsync_dir(folder)
    return manifest


def verify_set(manifest: str | Path) -> bool:
    """True if every file the manifest lists is on disk with the listed SHA-256."""
    manifest = Path(manifest)
    try:
        files = json.loads(manifest.read_text())["files"]
        return all(_sha256(manifest.with_name(n)) == h for n, h in files.items())
    except (OSError, ValueError, KeyError, TypeError):
        return False


def _roll_forward(folder: Path, group: dict[str, Path]) -> bool:
    """Complete an interrupted :func:`write_set` if its manifest was fully written."""
    for name, tmp in group.items():
        try:
            files = json.loads(tmp.read_text())["files"]
        except (OSError, ValueError, KeyError, TypeError):
            continue
        if not isinstance(files, dict) or set(files) | {name} != set(group) | set(files):
            continue
        sources = {}
        for member, digest in files.items():
            src = group.get(member, folder / member)
            if not src.exists() or _sha256(src) != digest:
                break
            sources[member] = src
        else:
            for member, src in sources.items():
                if src != folder / member:
                    os.replace(src, folder / member)
            os.replace(tmp, folder / name)
            _fsync_dir(folder)
            return True
    return False


def recover(folder: str | Path, names: set[str] | None = None) -> None:
    """Finish or remove the leftovers of writers that died (their PID is gone).

    Only temporary names of this module's pattern are touched, and with ``names`` only
    those of these outputs. A set whose manifest was completely written is rolled forward;
    a folder exchange that stopped half way is undone; everything else is deleted.
    """
    folder = Path(folder)
    groups: dict[str, dict[str, Path]] = {}
    olds = []
    try:
        entries = list(folder.iterdir())
    except OSError:
        return
    for p in entries:
        m = _TMP.match(p.name)
        if not m or (names is not None and m["name"] not in names) or _alive(int(m["pid"])):
            continue
        if m["kind"] == "old":
            olds.append((p, folder / m["name"]))
        else:
            groups.setdefault(f"{m['pid']}-{m['token']}", {})[m["name"]] = p
    for group in groups.values():
        if _roll_forward(folder, group):
            continue
        for p in group.values():
            _remove(p)
    for old, target in olds:
        if target.exists():
            _remove(old)
        else:
            os.replace(old, target)


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p, ignore_errors=True)
    else:
        p.unlink(missing_ok=True)


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically with renameat2(RENAME_EXCHANGE); False if unsupported."""
    libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
    fn = getattr(libc, "renameat2", None)
    if fn is None:
        return False
    at_fdcwd, rename_exchange = -100, 2
    rc = fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange)
    return rc == 0


@contextlib.contextmanager
def replace_folder(path: str | Path) -> Iterator[Path]:
    """Yield a temporary sibling folder to write into; on success it replaces ``path``
    as a whole (atomically where the OS can exchange two names), on failure it is removed.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    recover(path.parent, {path.name})
    token = _token()
    tmp = _tmp_name(path, token)
    tmp.mkdir()
    try:
        yield tmp
        for f in tmp.rglob("*"):
            if f.is_file():
                with open(f, "rb") as fh:
                    os.fsync(fh.fileno())
        _fsync_dir(tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if path.exists() and _exchange(tmp, path):
        _fsync_dir(path.parent)
        shutil.rmtree(tmp, ignore_errors=True)  # now the old folder
        return
    old = _tmp_name(path, token, "old")
    if path.exists():
        os.replace(path, old)
    os.replace(tmp, path)
    _fsync_dir(path.parent)
    shutil.rmtree(old, ignore_errors=True)
