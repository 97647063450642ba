"""Reading and writing files: point CSVs, LAS/LAZ point clouds, atomic output."""

from .atomic import atomic_write_bytes, atomic_write_text
from .cloud import (
    CloudInfo,
    CloudTransformResult,
    cloud_dask_xyz,
    cloud_info,
    iter_cloud_xyz,
    read_cloud_xyz,
    transform_cloud,
    transform_cloud_dask,
    write_cloud,
)
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
    "CloudInfo",
    "CloudTransformResult",
    "PointBlock",
    "PointBlocks",
    "PointPairs",
    "PointTable",
    "PointWriter",
    "atomic_write_bytes",
    "atomic_write_text",
    "cloud_dask_xyz",
    "cloud_info",
    "format_points_csv",
    "iter_cloud_xyz",
    "join_points",
    "parse_points",
    "read_cloud_xyz",
    "read_point_pairs",
    "read_points",
    "transform_cloud",
    "transform_cloud_dask",
    "write_cloud",
    "write_points",
]
