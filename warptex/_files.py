"""What every file writer and reader of ``warptex`` shares: checked paths, atomic writes, and
pixel arrays checked and converted to float32 ``[H, W, C]``.

Writers are atomic: :func:`_atomic_output` yields a temporary name in the target's folder and
renames it onto the target only once the file is complete; temporaries left by a killed writer are
removed by the next write of that file.
"""

from __future__ import annotations

import os
import re
import secrets
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np


def _as_image(image, func: str) -> np.ndarray:
    """Validate array-like pixels and return them as a float32 [H, W, C] array (always a new array)."""
    try:
        array = np.asarray(image)
    except ValueError as exc:  # ragged nested sequences
        raise ValueError(f"{func}(): image must be a rectangular array of numbers: {exc}") from None
    if not (np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)
            or array.dtype == np.bool_):
        raise TypeError(f"{func}(): image must hold real numbers, got dtype {array.dtype}")
    if array.ndim == 2:
        array = array[..., None]
    if array.ndim != 3:
        raise ValueError(f"{func}(): image must be shaped [H, W] or [H, W, C], got shape {array.shape}")
    if 0 in array.shape:
        raise ValueError(f"{func}(): image must not be empty, got shape {array.shape}")
    return array.astype(np.float32, copy=True)


def _fspath(path, func: str) -> str:
    try:
        return os.fsdecode(path)
    except TypeError:
        raise TypeError(f"{func}(): path must be str or os.PathLike, got {type(path).__name__}") from None


def _checked_input_path(path, func: str) -> str:
    path = _fspath(path, func)
    if not os.path.exists(path):
        raise FileNotFoundError(f"{func}(): file not found: '{path}'")
    if os.path.isdir(path):
        raise ValueError(f"{func}(): '{path}' is a directory, not an image file")
    return path


def _checked_output_path(path, func: str) -> str:
    path = _fspath(path, func)
    if os.path.isdir(path):
        raise ValueError(f"{func}(): '{path}' is a directory")
    folder = os.path.dirname(os.path.abspath(path))
    while not os.path.exists(folder):  # the folders to create: their first existing ancestor must be a folder
        folder = os.path.dirname(folder)
    if not os.path.isdir(folder):
        raise NotADirectoryError(f"{func}(): cannot write '{path}': '{folder}' is a file, not a folder")
    return path


@contextmanager
def _atomic_output(path: str) -> Iterator[str]:
    """Yield a temporary path next to ``path``; on success move it onto ``path``, on error remove it.

    The temporary name (``.name.<pid>-<random>.tmp.png``) keeps the real extension in case an
    encoder picks the format from it, and names the writing process: temporaries of ``path`` left
    by a process that no longer exists (killed mid-write) are removed here. It is created with
    ``os.open`` so the final file gets the usual umask-based permissions.
    """
    directory, base = os.path.split(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    _remove_stale_temporaries(directory, base)
    tmp = os.path.join(directory, f".{base}.{os.getpid()}-{secrets.token_hex(6)}.tmp{os.path.splitext(base)[1]}")
    os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    try:
        yield tmp
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.remove(tmp)
        except FileNotFoundError:
            pass
        raise


def _remove_stale_temporaries(directory: str, base: str) -> None:
    pattern = re.compile(re.escape(f".{base}.") + r"(\d+)-[0-9a-f]{12}\.tmp" + re.escape(os.path.splitext(base)[1]) + "$")
    for name in os.listdir(directory):
        match = pattern.match(name)
        if match and not process_alive(int(match.group(1)), os.path.join(directory, name)):
            try:
                os.remove(os.path.join(directory, name))
            except OSError:
                pass


def process_alive(pid: int, path: str | os.PathLike) -> bool:
    """Whether process ``pid``, which made ``path``, may still be writing it. POSIX: whether the
    process exists on this machine. Windows, where probing a process can end it: whether ``path``
    is younger than a day."""
    if pid == os.getpid():
        return True
    if os.name != "nt":
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except OSError:
            pass  # exists but is not ours (PermissionError), or we cannot tell: leave it
        return True
    try:
        return time.time() - os.stat(path).st_mtime < 86400.0
    except OSError:
        return False


class _RowFile:
    """A file written in bands of rows to a temporary beside ``path`` and renamed onto it by
    :meth:`close` once all ``height`` rows are written; any error (or :meth:`abort`) removes it,
    so nothing appears at ``path``. Subclasses call :meth:`_open` once their header is ready, count
    rows in ``_rows``, and write what follows the last row in :meth:`_finish`; used as a context
    manager, it closes on success and aborts on error."""

    path: str
    height: int
    _rows: int
    _file = None

    def _open(self):
        """The temporary file, open for writing."""
        self._atomic = _atomic_output(self.path)
        self._file = open(self._atomic.__enter__(), "wb")  # noqa: SIM115 (closed in close/abort)
        return self._file

    def _finish(self) -> None:
        """Write what follows the last row (the file is still open)."""

    @property
    def rows_written(self) -> int:
        return self._rows

    def close(self) -> None:
        """Finish the file and rename it onto ``path``: every row must have been written."""
        if self._file is None:
            return
        if self._rows != self.height:
            self.abort()
            raise ValueError(f"{type(self).__name__}.close(): {self._rows} of {self.height} rows were written; the file is removed")
        try:
            self._finish()
            self._file.close()
            self._file = None
            self._atomic.__exit__(None, None, None)
        except BaseException as err:
            self.abort(err)
            raise

    def abort(self, error: BaseException | None = None) -> None:
        """Stop and remove the partial file (nothing appears at ``path``)."""
        if self._file is None:
            return
        self._file.close()
        self._file = None
        err = error if error is not None else RuntimeError("aborted")
        try:
            self._atomic.__exit__(type(err), err, None)
        except BaseException:  # _atomic_output re-raises what it was given: the file is gone
            pass

    def __enter__(self):
        return self

    def __exit__(self, kind, error, trace) -> None:
        if error is None:
            self.close()
        else:
            self.abort(error)
