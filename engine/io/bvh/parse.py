"""Reading a BVH file: the HIERARCHY section (nodes, offsets, channels) and the MOTION section
(one line of channel values per frame), in file units, before any mapping.

Every problem raises :class:`InvalidInput` naming the file and the line. The file is read
line by line and the motion array grows with the frame lines actually read, so memory follows
what the file holds, never what its header announces; :class:`BvhLimits` refuse a file as
soon as it is over one of them (issue 26: a 200 KB file announcing 100 000 frames).
"""

from __future__ import annotations

import io
import itertools
import math
import os
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from engine.errors import InvalidInput

_CHANNELS = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")

#: Frames allocated at first; the array doubles from there up to the header's count, so a
#: header that lies costs nothing until the lines are there.
_FIRST_BLOCK = 4096

_TOKEN = re.compile(r"\S+")


@dataclass(frozen=True)
class BvhLimits:
    """What a BVH file may hold before it is refused, checked while it is read: joints and
    channels as the hierarchy comes, frames and duration on the MOTION header (before any
    frame is stored), frame lines as they are counted.

    They bound the parsed file to ``max_frames x max_channels`` values (442 MB at the
    defaults; a file's values also stay under 4 times its size, each taking two characters
    at least).

    Attributes
    ----------
    max_frames : int
        Most frames, as announced by ``Frames:`` and as frame lines counted (a file may
        not hold more lines than this either). 36 000 is 10 minutes at 60 fps.
    max_duration_s : float
        Longest motion, first to last frame: ``(Frames - 1) x Frame Time``, seconds.
    max_joints : int
        Most nodes in the hierarchy, end sites included.
    max_channels : int
        Most channels over all joints, i.e. values per frame line (6 per joint).
    """

    max_frames: int = 36_000
    max_duration_s: float = 600.0
    max_joints: int = 256
    max_channels: int = 6 * 256

    def __post_init__(self) -> None:
        for k in ("max_frames", "max_duration_s", "max_joints", "max_channels"):
            v = getattr(self, k)
            if not (isinstance(v, int | float) and v > 0):
                raise ValueError(f"BvhLimits.{k} must be positive, got {v!r}")


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


def read_bvh(path: str | os.PathLike, limits: BvhLimits | None = None) -> BvhFile:
    """Parse a BVH file (text, LF, CRLF or CR line ends).

    Parameters
    ----------
    path : str or path-like
    limits : BvhLimits, optional
        Refuse files over these; None (the default) for files one trusts, e.g. local ones.

    Returns
    -------
    BvhFile

    Raises
    ------
    InvalidInput
        When the file is missing, unreadable, malformed or over ``limits``; the message
        names the line.
    """
    p = Path(path)
    try:
        with open(p, encoding="utf-8", errors="replace") as f:
            return _parse(f, p.name, limits)
    except OSError as exc:
        raise InvalidInput(f"cannot read BVH file {p}: {exc.strerror or exc}") from None


def parse_bvh(text: str, *, name: str = "<string>", limits: BvhLimits | None = None) -> BvhFile:
    """Parse the text of a BVH file; see :func:`read_bvh`."""
    return _parse(io.StringIO(text, newline=None), name, limits)


def _parse(stream: Iterable[str], name: str, limits: BvhLimits | None) -> BvhFile:
    lines = _content_lines(stream)
    first = next(lines, None)
    if first is None or first[1].upper() != "HIERARCHY":
        raise InvalidInput(f"{name} is not a BVH file (it must start with HIERARCHY)")
    hierarchy = _parse_hierarchy(lines, name, limits)
    frame_time, values = _parse_motion(lines, hierarchy[3], name, limits)
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


def _content_lines(stream: Iterable[str]) -> Iterator[tuple[int, str]]:
    """(index, stripped text) of each non-blank line, read lazily."""
    for i, line in enumerate(stream):
        text = line.strip()
        if text:
            yield i, text


def _n_tokens(line: str) -> int:
    """Words on a line, counted without splitting it (error messages of huge lines)."""
    return sum(1 for _ in _TOKEN.finditer(line))


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
    limits: BvhLimits | None = None
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
            self._offset(tokens, line, i)
        elif key == "CHANNELS":
            self._channels(tokens, line, i)
        else:
            raise _err(self.name, i, f"unexpected {tokens[0][:40]!r} in the HIERARCHY section")

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
        cap = self.limits.max_joints if self.limits else None
        if cap is not None and len(self.names) >= cap:
            raise InvalidInput(
                f"{self.name} has more than {cap} joints (end sites included); "
                f"at most {cap} are accepted"
            )
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

    def _offset(self, tokens: list[str], line: str, i: int) -> None:
        """``OFFSET x y z`` of the innermost open node, file units."""
        if not self.stack:
            raise _err(self.name, i, "OFFSET outside of a joint")
        if len(tokens) != 4:
            raise _err(self.name, i, f"OFFSET needs 3 numbers, got {_n_tokens(line) - 1}")
        self.offsets[self.stack[-1]] = _floats(tokens[1:], self.name, i, "OFFSET values")
        self.has_offset[self.stack[-1]] = True

    def _channels(self, tokens: list[str], line: str, i: int) -> None:
        """``CHANNELS n name ...`` of the innermost open joint (an End Site has none)."""
        if not self.stack or self.ends[self.stack[-1]]:
            raise _err(self.name, i, "CHANNELS outside of a joint")
        try:
            n_chans = int(tokens[1])
        except (IndexError, ValueError):
            raise _err(self.name, i, "CHANNELS needs a count") from None
        self._check_channel_count(n_chans)
        chans = tokens[2:]
        if n_chans != len(chans):
            listed = _n_tokens(line) - 2
            raise _err(self.name, i, f"CHANNELS says {n_chans} channels but lists {listed}")
        # channel names are matched case-insensitively and stored in their canonical spelling
        canon = {c.lower(): c for c in _CHANNELS}
        bad = [c for c in chans if c.lower() not in canon]
        if bad:
            raise _err(self.name, i, f"unknown channel {bad[0]!r}")
        self.channels[self.stack[-1]] = [canon[c.lower()] for c in chans]

    def _check_channel_count(self, n_chans: int) -> None:
        """Refuse the innermost joint's ``n_chans`` channels when they go over the limit."""
        if self.limits is None:
            return
        cap = self.limits.max_channels
        others = sum(map(len, self.channels)) - len(self.channels[self.stack[-1]])
        if others + n_chans > cap:
            raise InvalidInput(
                f"{self.name} has more than {cap} channels; at most {cap} are accepted"
            )

    def max_split(self) -> int:
        """How many words of a line are worth splitting (str.split's maxsplit): a CHANNELS
        line over the limit is refused on its count, so longer lines are never split."""
        return -1 if self.limits is None else self.limits.max_channels + 2


def _joint_name(tokens: list[str], line: str) -> str:
    """The name after ROOT or JOINT (it may contain spaces); "" when there is none."""
    return line.split(None, 1)[1].strip() if len(tokens) > 1 else ""


def _parse_hierarchy(
    lines: Iterator[tuple[int, str]], name: str, limits: BvhLimits | None
) -> _Hierarchy:
    """Read the HIERARCHY section up to and including the MOTION line.

    Returns the nodes (:data:`_Hierarchy`); raises :class:`InvalidInput` naming the line of
    the first problem.
    """
    reader = _HierarchyReader(name, limits)
    for i, line in lines:
        opens = line.endswith("{") and line != "{"  # "JOINT name {" on one line
        if opens:
            line = line[:-1].strip()
        tokens = line.split(None, reader.max_split())
        key = tokens[0].upper()
        if key == "MOTION":
            return reader.finish(i)
        if reader.pending is not None and key != "{":
            raise _err(
                name, i, f"expected '{{' after {reader.names[reader.pending]!r}, got {line[:40]!r}"
            )
        reader.read(key, tokens, line, i, opens)
    raise InvalidInput(f"{name}: no MOTION section (the file ends inside the hierarchy)")


def _header(lines: Iterator[tuple[int, str]], key: str, name: str) -> tuple[int, str]:
    """The next line, which must start with ``key``: its index and the text after the key."""
    item = next(lines, None)
    if item is None:
        raise InvalidInput(f"{name}: the MOTION section ends before '{key}'")
    i, line = item
    if not line.lower().startswith(key.lower()):
        raise _err(name, i, f"expected '{key}', got {line[:40]!r}")
    return i, line[len(key) :].strip()


def _parse_motion(
    lines: Iterator[tuple[int, str]],
    channels: list[list[str]],
    name: str,
    limits: BvhLimits | None,
) -> tuple[float, np.ndarray]:
    """The MOTION section after its keyword: Frame Time and values (T, C).

    The header is checked against ``limits`` before any frame line is read.
    """
    ln, frames_s = _header(lines, "Frames:", name)
    try:
        n_frames = int(frames_s)
    except ValueError:
        raise _err(name, ln, f"Frames must be an integer, got {frames_s[:40]!r}") from None
    if n_frames <= 0:
        raise _err(name, ln, f"the file has {n_frames} frames; at least one is needed")
    if limits is not None and n_frames > limits.max_frames:
        raise InvalidInput(
            f"{name} has {n_frames} frames; at most {limits.max_frames} are accepted"
        )
    ln, ft_s = _header(lines, "Frame Time:", name)
    (frame_time,) = _floats([ft_s], name, ln, "Frame Time")
    if frame_time <= 0:
        raise _err(name, ln, f"Frame Time must be positive, got {frame_time}")
    duration_s = (n_frames - 1) * frame_time  # first to last frame, as Motion.duration_s
    if limits is not None and duration_s > limits.max_duration_s:
        raise InvalidInput(
            f"{name} lasts {duration_s:.1f} s ({n_frames} frames at {1 / frame_time:.4g} "
            f"fps); at most {limits.max_duration_s:g} s are accepted"
        )
    values = _read_frames(lines, n_frames, sum(len(c) for c in channels), name)
    if limits is not None:
        _refuse_extra_lines(lines, n_frames, limits.max_frames, name)
    return frame_time, values


def _read_frames(
    lines: Iterator[tuple[int, str]], n_frames: int, n_ch: int, name: str
) -> np.ndarray:
    """The next ``n_frames`` lines as values (n_frames, n_ch), stored as they are read."""
    values = np.empty((min(n_frames, _FIRST_BLOCK), n_ch))
    at: list[int] = []  # line index of each frame, for the NaN message
    for k, line in itertools.islice(lines, n_frames):
        f = len(at)
        if f == len(values):  # doubles, up to the header's count
            values = np.concatenate([values, np.empty((min(f, n_frames - f), n_ch))])
        tokens = line.split(None, n_ch)  # one word too many is enough to refuse the line
        if len(tokens) != n_ch:
            msg = f"frame {f} has {_n_tokens(line)} values, the hierarchy has {n_ch} channels"
            raise _err(name, k, msg)
        try:
            values[f] = np.array(tokens, dtype=float)
        except ValueError:
            bad = next(t for t in tokens if not _is_number(t))
            raise _err(name, k, f"frame {f}: {bad[:40]!r} is not a number") from None
        at.append(k)
    if len(at) < n_frames:
        raise InvalidInput(
            f"{name}: truncated file: the header announces {n_frames} frames, "
            f"only {len(at)} frame lines follow"
        )
    if not np.all(np.isfinite(values)):
        f = int(np.flatnonzero(~np.all(np.isfinite(values), axis=1))[0])
        raise _err(name, at[f], f"frame {f} contains NaN or infinite values")
    return values


def _refuse_extra_lines(
    lines: Iterator[tuple[int, str]], n_frames: int, max_frames: int, name: str
) -> None:
    """Lines after the announced frames are ignored, but counted up to the limit: a header
    that understates its frames cannot carry an unbounded file past it."""
    extra = sum(1 for _ in itertools.islice(lines, max_frames - n_frames + 1))
    if n_frames + extra > max_frames:
        raise InvalidInput(
            f"{name} has more than {max_frames} frame lines (its header announces "
            f"{n_frames} frames); at most {max_frames} are accepted"
        )


def _is_number(t: str) -> bool:
    try:
        float(t)
    except ValueError:
        return False
    return True
