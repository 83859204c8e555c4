"""Files in and out: point clouds, meshes and NURBS parameters, as people have them.

The format is chosen by the file's content where it has a signature (PLY, OFF, PCD,
NPY/NPZ, STL, JSON) and by its extension otherwise, so a file whose extension lies
is still read as what it is. Every reader returns float64 coordinates; every writer
is atomic (a temporary file renamed into place). Errors are
:class:`~nurbskit.errors.InputError` messages that name the file and the problem.

Example:
    >>> import nurbskit
    >>> cloud = nurbskit.io.read_points("scan.pcd")  # doctest: +SKIP
    >>> cloud.points.shape, cloud.dropped  # doctest: +SKIP
    ((248312, 3), 58888)

See docs/io.md for the table of formats.
"""

from ._base import Mesh, PointCloud
from .formats import detect_format
from .mesh import read_mesh, write_mesh
from .nurbs import read_nurbs, read_weights, to_geomdl_json, write_nurbs
from .points import read_points, write_points

__all__ = [
    "PointCloud", "Mesh",
    "read_points", "write_points", "read_mesh", "write_mesh",
    "read_nurbs", "write_nurbs", "read_weights", "to_geomdl_json",
    "detect_format",
]
