"""Split JSON Lines recordings into partitions of bounded size by byte range."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class Partition:
    """A run of consecutive lines of one recording.

    Attributes
    ----------
    index : int
        Position in the campaign (names the output file ``part-00007.jsonl``).
    path : str
        The recording (absolute path, as every worker must read it).
    start, end : int
        Byte range ``[start, end)`` of the lines in the recording.
    first_line : int
        1-based number of the partition's first line in the recording.
    lines : int
        Lines in the range (blank lines included; they produce no output).
    """

    index: int
    path: str
    start: int
    end: int
    first_line: int
    lines: int

    @property
    def key(self) -> str:
        """Identity of the input: a re-planned campaign with the same key is the same work."""
        return hashlib.sha256(f"{self.path}|{self.start}|{self.end}".encode()).hexdigest()[:16]

    @property
    def output_name(self) -> str:
        return f"part-{self.index:05d}.jsonl"

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def plan_partitions(paths: Sequence[Path], max_lines: int) -> list[Partition]:
    """Partitions of at most ``max_lines`` lines over ``paths``, in order (one pass per file,
    reading only line ends)."""
    if max_lines < 1:
        raise ValueError("partition size must be at least 1 line")
    parts: list[Partition] = []
    for path in paths:
        path = Path(path).resolve()
        with open(path, "rb") as fh:
            start = pos = 0
            first = line = 1
            count = 0
            for raw in fh:
                pos += len(raw)
                count += 1
                line += 1
                if count == max_lines:
                    parts.append(Partition(len(parts), str(path), start, pos, first, count))
                    start, first, count = pos, line, 0
            if count:
                parts.append(Partition(len(parts), str(path), start, pos, first, count))
    return parts


def read_lines(part: Partition) -> list[bytes]:
    """The partition's lines (bytes, newline stripped)."""
    with open(part.path, "rb") as fh:
        fh.seek(part.start)
        data = fh.read(part.end - part.start)
    return data.splitlines()
