"""Reading and writing files: point CSVs, atomic output."""

from .atomic import atomic_write_bytes, atomic_write_text
from .points import (
    PointBlock,
    PointBlocks,
    PointPairs,
    PointTable,
    PointWriter,
    format_points_csv,
    join_points,
    parse_points,
    read_point_pairs,
    read_points,
    write_points,
)

__all__ = [
    "PointBlock",
    "PointBlocks",
    "PointPairs",
    "PointTable",
    "PointWriter",
    "atomic_write_bytes",
    "atomic_write_text",
    "format_points_csv",
    "join_points",
    "parse_points",
    "read_point_pairs",
    "read_points",
    "write_points",
]
