"""Stage outputs on disk: one compressed ``.npz`` per stage, written atomically.

Arrays travel between processes as files (STYLE.md), so a stage's output is a set of named
arrays plus a small JSON header. Writing goes to a temporary name in the same folder and is
renamed into place, so a reader never sees half a file and a killed writer leaves no output.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import IO, Any, Protocol, cast

import numpy as np

from engine.errors import InvalidInput

_META = "__meta__"


class _SaveNamedArrays(Protocol):
    def __call__(self, file: IO[bytes], /, **arrays: np.ndarray) -> None: ...


# np.savez_compressed stores keyword arguments as named arrays, but numpy >= 2.1 also has an
# ``allow_pickle`` keyword, so its stubs (rightly) refuse **dict[str, ndarray]. save_arrays
# rejects that name, so here every keyword is an array: the narrower signature is exact.
_savez_named = cast(_SaveNamedArrays, np.savez_compressed)


def save_arrays(
    path: str | os.PathLike, arrays: dict[str, np.ndarray], meta: dict[str, Any]
) -> Path:
    """Write named arrays and a JSON-able header to ``path`` atomically."""
    if "allow_pickle" in arrays:
        raise ValueError("arrays: 'allow_pickle' is not a valid array name (numpy keyword)")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = dict(arrays)
    payload[_META] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            _savez_named(fh, **payload)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def load_arrays(path: str | os.PathLike) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read what :func:`save_arrays` wrote: (arrays, header)."""
    try:
        with np.load(Path(path), allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files if k != _META}
            meta = json.loads(bytes(data[_META]).decode()) if _META in data.files else {}
    except FileNotFoundError:
        raise
    except (OSError, ValueError, KeyError) as exc:
        raise InvalidInput(f"stage file {Path(path).name} is unreadable: {exc}") from exc
    return arrays, meta


def pack_masks(masks: np.ndarray) -> tuple[np.ndarray, tuple[int, ...]]:
    """Boolean masks (..., H, W) as bits: 8x smaller before compression."""
    masks = np.asarray(masks, dtype=bool)
    return np.packbits(masks, axis=-1), masks.shape


def unpack_masks(bits: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    return np.unpackbits(bits, axis=-1, count=shape[-1]).astype(bool).reshape(shape)
