"""A run's output files appear together or not at all.

``warptex render``, ``demo``, ``fit`` and ``bake`` (and :func:`warptex.export_gltf`) each write
several files that belong together (a render and its G-buffer; fitted maps and their summary; a
glTF asset and its textures). :func:`output_set` stages them in a hidden
folder inside the output folder and moves them into place only once every one is written, in one
quick loop of renames (each atomic; the loop takes microseconds). An error or Ctrl-C removes the
staging folder and leaves the previous run's files as they were. A staging folder left by a
killed process (``SIGKILL``, power loss) is removed by the next run into the same folder.
"""

from __future__ import annotations

import os
import re
import secrets
import shutil
import stat
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import warp as wp

from warptex import io
from warptex._interrupts import interrupts_deferred

_STAGING = re.compile(r"^\.warptex-(\d+)-[0-9a-f]+\.partial$")


@contextmanager
def output_set(out_dir: str | os.PathLike) -> Iterator[Path]:
    """Stage a run's files: yields a folder to write them into; on success they are moved into
    ``out_dir`` (created if missing), on any exception none are and the staging folder is removed.
    Sub-folders are not supported: write files only."""
    out = check_output_folder("output_set", out_dir)
    out.mkdir(parents=True, exist_ok=True)
    remove_stale_staging(out)
    staging = out / f".warptex-{os.getpid()}-{secrets.token_hex(4)}.partial"
    staging.mkdir()
    try:
        yield staging
        with interrupts_deferred():  # a Ctrl-C among the renames would leave old and new files mixed
            for item in sorted(staging.iterdir()):
                if not item.name.startswith("."):  # a writer's own hidden temporaries stay behind
                    os.replace(item, out / item.name)
            global _commits
            _commits += 1
    finally:
        shutil.rmtree(staging, ignore_errors=True)


_commits = 0  # output sets moved into place by this process


def commits() -> int:
    """How many output sets this process has moved into place: a Ctrl-C that arrives after a
    job's set is in place (:func:`output_set` defers it past the renames) finds this changed."""
    return _commits


# Tries to create and write into a new output folder: processes that check the same one at once
# (the ranks of a distributed fit) each remove what they created, possibly under another's feet.
_PROBE_ATTEMPTS = 20


def check_output_folder(func: str, out_dir: str | os.PathLike) -> Path:
    """``out_dir`` as a ``Path``, or an ``OSError`` naming ``func`` and the folder when it exists as
    a file, cannot be created or cannot be written: called before a job's work, so that a bad
    folder is reported before the work is done. Folders it creates to find out are removed again."""
    out = Path(out_dir)
    try:
        kind = out.stat().st_mode  # one look: another process may be removing the folder meanwhile
    except (FileNotFoundError, NotADirectoryError):
        kind = None
    if kind is not None and not stat.S_ISDIR(kind):
        raise NotADirectoryError(f"{func}(): the output folder {str(out)!r} is a file")
    missing = []
    for folder in (out, *out.absolute().parents):
        if folder.exists():
            break
        missing.append(folder)
    try:
        for attempt in range(_PROBE_ATTEMPTS):
            probe = out / f".warptex-{os.getpid()}-{secrets.token_hex(4)}.probe"
            try:
                out.mkdir(parents=True, exist_ok=True)
                probe.touch()
            except (FileNotFoundError, FileExistsError):  # another process checking the same new folder removed it meanwhile (ranks of one job)
                if attempt + 1 == _PROBE_ATTEMPTS:
                    raise
                continue
            probe.unlink()
            break
    except OSError as err:
        raise type(err)(f"{func}(): cannot write into the output folder {str(out)!r}: {err.strerror or err}") from None
    finally:
        for folder in missing:  # deepest first
            try:
                folder.rmdir()
            except OSError:
                pass
    return out


def remove_stale_staging(out: Path) -> list[Path]:
    """Remove the staging folders in ``out`` whose process is gone; the paths removed."""
    removed = []
    for item in out.iterdir():
        match = _STAGING.match(item.name)
        if match and item.is_dir() and not io.process_alive(int(match.group(1)), item):
            shutil.rmtree(item, ignore_errors=True)
            removed.append(item)
    return removed


def check_memory(func: str, what: str, needed_bytes: float, device=None, hint: str = "use a smaller resolution") -> None:
    """Raise ``MemoryError`` naming ``what`` when a job needs more memory than this machine has
    available (Linux: ``MemAvailable``; elsewhere the allocation itself reports it), or, on a CUDA
    ``device``, more than the device has free, instead of letting the job run the machine out of
    memory or fail deep inside an allocation."""
    available = _available_memory()
    where = "available"
    if device is not None and wp.get_device(device).is_cuda:
        available, where = getattr(wp.get_device(device), "free_memory", None), f"free on {wp.get_device(device)}"
    if available is not None and needed_bytes > available:
        raise MemoryError(
            f"{func}(): {what} needs about {needed_bytes / 2**30:.1f} GiB of memory, but "
            f"{available / 2**30:.1f} GiB is {where}; {hint}"
        )


def _available_memory() -> int | None:
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None
