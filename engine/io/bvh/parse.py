"""Reading a BVH file: the HIERARCHY section (nodes, offsets, channels) and the MOTION section
(one line of channel values per frame), in file units, before any mapping.

Every problem raises :class:`InvalidInput` naming the file and the line.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from engine.errors import InvalidInput

_CHANNELS = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")


@dataclass(frozen=True)
class BvhFile:
    """A parsed BVH file, in file units, before any mapping.

    Attributes
    ----------
    names : tuple of str
        Joint names in file order (depth first), end sites named ``<parent>/End``. N nodes.
    parents : ndarray of int, shape (N,)
        Parent node of each node, -1 for the root; parents come before children.
    offsets : ndarray, shape (N, 3)
        OFFSET of each node in its parent's frame, file units.
    channels : tuple of tuple of str
        Channel names of each node (empty for end sites).
    is_end_site : ndarray of bool, shape (N,)
    frame_time : float
        Seconds per frame.
    values : ndarray, shape (T, C)
        Channel values per frame, in channel order of the hierarchy; degrees and file units.
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    is_end_site: np.ndarray
    frame_time: float
    values: np.ndarray

    @property
    def frames(self) -> int:
        return int(self.values.shape[0])

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    def channel_slices(self) -> list[slice]:
        """Column range of each node's channels in :attr:`values`."""
        out, start = [], 0
        for ch in self.channels:
            out.append(slice(start, start + len(ch)))
            start += len(ch)
        return out


def read_bvh(path: str | os.PathLike) -> BvhFile:
    """Parse a BVH file (text, LF or CRLF).

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    BvhFile

    Raises
    ------
    InvalidInput
        When the file is missing, unreadable or malformed; the message names the line.
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise InvalidInput(f"cannot read BVH file {p}: {exc.strerror or exc}") from None
    text = raw.decode("utf-8", errors="replace")
    return parse_bvh(text, name=p.name)


def parse_bvh(text: str, *, name: str = "<string>") -> BvhFile:
    """Parse the text of a BVH file; see :func:`read_bvh`."""
    lines = text.splitlines()
    first = next((i for i, line in enumerate(lines) if line.strip()), None)
    if first is None or lines[first].strip().upper() != "HIERARCHY":
        raise InvalidInput(f"{name} is not a BVH file (it must start with HIERARCHY)")
    motion_line, hierarchy = _parse_hierarchy(lines, first + 1, name)
    frame_time, values = _parse_motion(lines, motion_line, hierarchy[3], name)
    names, parents, offsets, channels, ends = hierarchy
    return BvhFile(
        names=tuple(names),
        parents=np.array(parents, dtype=int),
        offsets=np.array(offsets, dtype=float).reshape(-1, 3),
        channels=tuple(tuple(c) for c in channels),
        is_end_site=np.array(ends, dtype=bool),
        frame_time=frame_time,
        values=values,
    )


def _err(name: str, line: int, msg: str) -> InvalidInput:
    return InvalidInput(f"{name}, line {line + 1}: {msg}")


def _floats(tokens: list[str], name: str, line: int, what: str) -> list[float]:
    try:
        out = [float(t) for t in tokens]
    except ValueError:
        raise _err(name, line, f"{what} must be numbers, got {' '.join(tokens)!r}") from None
    if not all(math.isfinite(v) for v in out):
        raise _err(name, line, f"{what} must be finite, got {' '.join(tokens)!r}")
    return out


#: What :func:`_parse_hierarchy` reads, per node in file order (N nodes): names, parents,
#: offsets (N, 3) in file units, channel names and end-site flags.
_Hierarchy = tuple[list[str], list[int], list[list[float]], list[list[str]], list[bool]]


@dataclass
class _HierarchyReader:
    """The HIERARCHY section read so far, one line at a time (mutable while parsing).

    Nodes are appended in file order (depth first). ``stack`` holds the nodes whose braces
    are open; ``pending`` is a node just declared whose ``{`` has not come yet.
    """

    name: str
    names: list[str] = field(default_factory=list)
    parents: list[int] = field(default_factory=list)
    offsets: list[list[float]] = field(default_factory=list)
    channels: list[list[str]] = field(default_factory=list)
    ends: list[bool] = field(default_factory=list)
    has_offset: list[bool] = field(default_factory=list)
    stack: list[int] = field(default_factory=list)
    pending: int | None = None

    def read(self, key: str, tokens: list[str], line: str, i: int, opens: bool) -> None:
        """One non-empty line ``i`` (its trailing ``{`` removed, ``opens`` says there was one)."""
        if key in ("ROOT", "JOINT") or (key == "END" and len(tokens) > 1):
            self._node(key, tokens, line, i, opens)
        elif key == "{":
            if self.pending is None:
                raise _err(self.name, i, "'{' without a joint")
            self.stack.append(self.pending)
            self.pending = None
        elif key == "}":
            if not self.stack:
                raise _err(self.name, i, "unmatched '}'")
            self.stack.pop()
        elif key == "OFFSET":
            self._offset(tokens, i)
        elif key == "CHANNELS":
            self._channels(tokens, i)
        else:
            raise _err(self.name, i, f"unexpected {tokens[0]!r} in the HIERARCHY section")

    def finish(self, i: int) -> _Hierarchy:
        """The hierarchy at the MOTION line ``i``, once every brace is closed."""
        if self.stack or self.pending is not None:
            raise _err(self.name, i, "MOTION before the hierarchy's braces are closed")
        if not self.names:
            raise _err(self.name, i, "the hierarchy has no ROOT joint")
        for n, ok in zip(self.names, self.has_offset, strict=True):
            if not ok:
                raise InvalidInput(f"{self.name}: joint {n!r} has no OFFSET")
        return self.names, self.parents, self.offsets, self.channels, self.ends

    def _node(self, key: str, tokens: list[str], line: str, i: int, opens: bool) -> None:
        """A ROOT, JOINT or End Site line: a new node under the innermost open one."""
        self._check_parent(key, tokens[0], i)
        parent = self.stack[-1] if self.stack else -1
        jname = self._end_name(parent) if key == "END" else _joint_name(tokens, line)
        if not jname:
            raise _err(self.name, i, f"{tokens[0]} without a name")
        self.names.append(jname)
        self.parents.append(parent)
        self.offsets.append([0.0, 0.0, 0.0])
        self.channels.append([])
        self.ends.append(key == "END")
        self.has_offset.append(False)
        self.pending = len(self.names) - 1
        if opens:
            self.stack.append(self.pending)
            self.pending = None

    def _check_parent(self, key: str, word: str, i: int) -> None:
        """One ROOT at the top level; every other node inside a joint that is no End Site."""
        if key == "ROOT":
            if self.stack or self.names:
                raise _err(self.name, i, "only one ROOT is supported, at the top level")
        elif not self.stack:
            raise _err(self.name, i, f"{word} outside of a ROOT")
        elif self.ends[self.stack[-1]]:
            raise _err(self.name, i, "an End Site cannot have children")

    def _end_name(self, parent: int) -> str:
        """``<parent>/End``, then ``<parent>/End2`` ... for a joint's further end sites."""
        base = f"{self.names[parent]}/End"
        k = sum(1 for n in self.names if n.startswith(base))
        return base if k == 0 else f"{base}{k + 1}"

    def _offset(self, tokens: list[str], i: int) -> None:
        """``OFFSET x y z`` of the innermost open node, file units."""
        if not self.stack:
            raise _err(self.name, i, "OFFSET outside of a joint")
        if len(tokens) != 4:
            raise _err(self.name, i, f"OFFSET needs 3 numbers, got {len(tokens) - 1}")
        self.offsets[self.stack[-1]] = _floats(tokens[1:], self.name, i, "OFFSET values")
        self.has_offset[self.stack[-1]] = True

    def _channels(self, tokens: list[str], i: int) -> None:
        """``CHANNELS n name ...`` of the innermost open joint (an End Site has none)."""
        if not self.stack or self.ends[self.stack[-1]]:
            raise _err(self.name, i, "CHANNELS outside of a joint")
        try:
            n_chans = int(tokens[1])
        except (IndexError, ValueError):
            raise _err(self.name, i, "CHANNELS needs a count") from None
        chans = tokens[2:]
        if n_chans != len(chans):
            raise _err(self.name, i, f"CHANNELS says {n_chans} channels but lists {len(chans)}")
        # channel names are matched case-insensitively and stored in their canonical spelling
        canon = {c.lower(): c for c in _CHANNELS}
        bad = [c for c in chans if c.lower() not in canon]
        if bad:
            raise _err(self.name, i, f"unknown channel {bad[0]!r}")
        self.channels[self.stack[-1]] = [canon[c.lower()] for c in chans]


def _joint_name(tokens: list[str], line: str) -> str:
    """The name after ROOT or JOINT (it may contain spaces); "" when there is none."""
    return line.split(None, 1)[1].strip() if len(tokens) > 1 else ""


def _parse_hierarchy(lines: list[str], start: int, name: str) -> tuple[int, _Hierarchy]:
    """Read the HIERARCHY section from line ``start`` up to the MOTION line.

    Returns the MOTION line's index and the nodes (:data:`_Hierarchy`); raises
    :class:`InvalidInput` naming the line of the first problem.
    """
    reader = _HierarchyReader(name)
    for i in range(start, len(lines)):
        line = lines[i].strip()
        if not line:
            continue
        opens = line.endswith("{") and line != "{"  # "JOINT name {" on one line
        if opens:
            line = line[:-1].strip()
        tokens = line.split()
        key = tokens[0].upper()
        if key == "MOTION":
            return i, reader.finish(i)
        if reader.pending is not None and key != "{":
            raise _err(
                name, i, f"expected '{{' after {reader.names[reader.pending]!r}, got {line!r}"
            )
        reader.read(key, tokens, line, i, opens)
    raise InvalidInput(f"{name}: no MOTION section (the file ends inside the hierarchy)")


def _parse_motion(lines: list[str], at: int, channels: list[list[str]], name: str):
    n_ch = sum(len(c) for c in channels)
    i = at + 1

    def header(key: str) -> tuple[int, str]:
        nonlocal i
        while i < len(lines) and not lines[i].strip():
            i += 1
        if i >= len(lines):
            raise InvalidInput(f"{name}: the MOTION section ends before '{key}'")
        line = lines[i].strip()
        if not line.lower().startswith(key.lower()):
            raise _err(name, i, f"expected '{key}', got {line[:40]!r}")
        i += 1
        return i - 1, line[len(key) :].strip()

    ln, frames_s = header("Frames:")
    try:
        n_frames = int(frames_s)
    except ValueError:
        raise _err(name, ln, f"Frames must be an integer, got {frames_s!r}") from None
    if n_frames <= 0:
        raise _err(name, ln, f"the file has {n_frames} frames; at least one is needed")
    ln, ft_s = header("Frame Time:")
    (frame_time,) = _floats([ft_s], name, ln, "Frame Time")
    if frame_time <= 0:
        raise _err(name, ln, f"Frame Time must be positive, got {frame_time}")
    rows = [(k, lines[k]) for k in range(i, len(lines)) if lines[k].strip()]
    if len(rows) < n_frames:
        raise InvalidInput(
            f"{name}: truncated file: the header announces {n_frames} frames, "
            f"only {len(rows)} frame lines follow"
        )
    values = np.empty((n_frames, n_ch))
    for f, (k, line) in enumerate(rows[:n_frames]):
        tokens = line.split()
        if len(tokens) != n_ch:
            raise _err(
                name, k, f"frame {f} has {len(tokens)} values, the hierarchy has {n_ch} channels"
            )
        try:
            values[f] = np.array(tokens, dtype=float)
        except ValueError:
            bad = next(t for t in tokens if not _is_number(t))
            raise _err(name, k, f"frame {f}: {bad!r} is not a number") from None
    if not np.all(np.isfinite(values)):
        f = int(np.flatnonzero(~np.all(np.isfinite(values), axis=1))[0])
        raise _err(name, rows[f][0], f"frame {f} contains NaN or infinite values")
    return frame_time, values


def _is_number(t: str) -> bool:
    try:
        float(t)
    except ValueError:
        return False
    return True
