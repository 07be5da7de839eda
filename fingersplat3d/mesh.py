"""Open3D adapter: a triangle mesh from a point cloud (screened Poisson + cleaning), and its writer.

:func:`mesh_from_cloud` runs Open3D's screened Poisson reconstruction, then removes what Poisson
invents where there are no points (the "balloon" that closes the surface behind an open scan):
vertices farther than a few point spacings from every input point, vertices of the lowest sample
density, and everything outside the cloud's slightly enlarged bounding box. The distance test does
most of the work: on a three-view finger the balloon holds 10-20% of the vertices, so a density
quantile alone either leaves millimetre-sized flaps (2%) or eats into real surface (20%).
pymeshlab then cleans the result: duplicate vertices and faces, non-manifold edges and vertices,
small isolated pieces, and optionally a quadric decimation to a triangle budget.

Open3D, pymeshlab and trimesh are imported lazily, inside the functions.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from .atomic import atomic_path

if TYPE_CHECKING:  # pragma: no cover
    import open3d as o3d

__all__ = ["MIN_POINTS", "SUPPORT_SPACINGS", "mesh_from_cloud", "write_mesh"]

MIN_POINTS = 100
"""Fewest points :func:`mesh_from_cloud` accepts: fewer cannot define a surface worth meshing."""

SUPPORT_SPACINGS = 3.0
"""Default ``support_distance`` of :func:`mesh_from_cloud`, in median point spacings of the cloud."""

_BOX_MARGIN = 0.02  # bounding-box enlargement, as a fraction of the cloud's diagonal
_MIN_PIECE = 0.05  # pieces whose diameter is under this fraction of the mesh diagonal are dropped
_NORMAL_NEIGHBOURS = 20


def _with_normals(cloud: "o3d.geometry.PointCloud") -> "o3d.geometry.PointCloud":
    """A copy of the cloud with unit normals: its own, or estimated and oriented ones.

    Given normals are used when at least 90% of them are finite and non-zero (voxel averaging
    leaves a few near-zero ones where opposite normals met); the others' points are dropped and
    the rest normalised. Otherwise normals are estimated from neighbours, propagated to one
    consistent sign, and the whole set is flipped if it points mostly toward the centroid: a
    finger (or any scan of a convex-ish shell) then has outward normals, which Poisson needs to
    put the inside behind the surface.
    """
    import open3d as o3d

    if cloud.has_normals():
        normals = np.asarray(cloud.normals)
        length = np.linalg.norm(normals, axis=1)
        usable = np.isfinite(length) & (length > 1e-6)
        if usable.mean() >= 0.9:
            keep = np.flatnonzero(usable)
            given = cloud.select_by_index(keep) if len(keep) < len(normals) else o3d.geometry.PointCloud(cloud)
            given.normals = o3d.utility.Vector3dVector(normals[keep] / length[keep, None])
            return given
    points = np.asarray(cloud.points)
    centred = points - points.mean(0)
    spread = np.linalg.svd(centred, compute_uv=False)  # principal extents, descending (accurate to rounding)
    if spread[1] <= 1e-7 * spread[0] or spread[0] == 0:
        raise ValueError("no normals can be obtained for the point cloud: its points are repeated or collinear")
    estimated = o3d.geometry.PointCloud(cloud.points)
    if cloud.has_colors():
        estimated.colors = cloud.colors
    estimated.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(_NORMAL_NEIGHBOURS))
    normals = np.asarray(estimated.normals)
    if not (np.all(np.isfinite(normals)) and np.all(np.linalg.norm(normals, axis=1) > 0.5)):
        raise ValueError("no normals could be estimated for the point cloud (are many of its points repeated?)")
    if spread[2] <= 1e-6 * spread[0]:  # a flat patch: one side is as good as the other, Delaunay would fail
        _, axes = np.linalg.eigh(centred.T @ centred)
        estimated.orient_normals_to_align_with_direction(axes[:, 0])
        return estimated
    try:
        estimated.orient_normals_consistent_tangent_plane(_NORMAL_NEIGHBOURS)
    except RuntimeError as error:
        first_line = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise ValueError(f"the point cloud's normals could not be oriented consistently ({first_line})") from None
    points, normals = np.asarray(estimated.points), np.asarray(estimated.normals)
    if np.sum((points - points.mean(0)) * normals) < 0:
        estimated.normals = o3d.utility.Vector3dVector(-normals)
    return estimated


def _clean(vertices: np.ndarray, triangles: np.ndarray, colors: np.ndarray | None,
           target_triangles: int | None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """pymeshlab cleaning (and decimation) of a triangle soup; returns arrays."""
    import pymeshlab

    if colors is not None:
        rgba = np.concatenate([colors, np.ones((len(colors), 1))], axis=1)
        mesh = pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=triangles, v_color_matrix=rgba)
    else:
        mesh = pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=triangles)
    meshes = pymeshlab.MeshSet()
    meshes.add_mesh(mesh)
    meshes.meshing_remove_duplicate_vertices()
    meshes.meshing_remove_duplicate_faces()
    meshes.meshing_remove_null_faces()
    meshes.meshing_repair_non_manifold_edges()
    meshes.meshing_repair_non_manifold_vertices()
    meshes.meshing_remove_connected_component_by_diameter(mincomponentdiag=pymeshlab.PercentageValue(100 * _MIN_PIECE))
    meshes.meshing_remove_unreferenced_vertices()
    if target_triangles is not None and meshes.current_mesh().face_number() > target_triangles:
        meshes.meshing_decimation_quadric_edge_collapse(targetfacenum=int(target_triangles), preservenormal=True,
                                                        preserveboundary=True, optimalplacement=True, autoclean=True)
    result = meshes.current_mesh()
    colors_out = result.vertex_color_matrix()[:, :3] if colors is not None else None
    return result.vertex_matrix(), result.face_matrix(), colors_out


def mesh_from_cloud(cloud: "o3d.geometry.PointCloud", *, depth: int = 8, density_quantile: float = 0.02,
                    support_distance: float | None = None, target_triangles: int | None = None) -> "o3d.geometry.TriangleMesh":
    """A cleaned triangle mesh of ``cloud`` by screened Poisson reconstruction.

    ``depth``: Poisson octree depth (the finest cell is the enlarged bounding cube / ``2**depth``;
    8 gives ~0.14 mm cells on a 33 mm finger scan). ``density_quantile``: vertices whose Poisson
    sample density falls in this lowest fraction are removed (0 keeps all). ``support_distance``:
    vertices farther than this from every input point are removed (None: ``SUPPORT_SPACINGS``
    times the cloud's median point spacing; ``math.inf`` keeps all). ``target_triangles``:
    quadric-decimate to about this many triangles when the mesh has more.

    The cloud's own normals are used when it has them (they must face outward, as
    :func:`fingersplat3d.geometry.view_point_cloud` makes them); otherwise they are estimated and
    oriented (a few seconds more per 10k points). Colours, when present, are carried onto the vertices. Vertex normals of the result
    are recomputed from its triangles. Raises ``ValueError`` for fewer than ``MIN_POINTS`` points,
    NaN/Inf points, normals that cannot be obtained, or an empty result.
    """
    import open3d as o3d

    if not isinstance(cloud, o3d.geometry.PointCloud):
        raise TypeError(f"expected an open3d.geometry.PointCloud, got {type(cloud).__name__}")
    if not 1 <= int(depth) <= 16:
        raise ValueError(f"Poisson depth must be between 1 and 16, got {depth}")
    if not 0.0 <= density_quantile < 1.0:
        raise ValueError(f"density_quantile must lie in [0, 1), got {density_quantile}")
    if support_distance is not None and not support_distance > 0:
        raise ValueError(f"support_distance must be positive (math.inf keeps every vertex), got {support_distance}")
    if target_triangles is not None and int(target_triangles) < 4:
        raise ValueError(f"target_triangles must be at least 4, got {target_triangles}")
    points = np.asarray(cloud.points)
    if len(points) < MIN_POINTS:
        raise ValueError(f"a point cloud of {len(points)} points is too small to mesh (at least {MIN_POINTS} are needed)")
    if not np.all(np.isfinite(points)):
        raise ValueError("the point cloud contains NaN or Inf coordinates")
    cloud = _with_normals(cloud)

    # One thread: Open3D's multi-threaded Poisson solver crashes now and then (SIGSEGV) when the CPU is saturated
    # (isl-org/Open3D#6828, #7229); it took down a CI test worker here. On a finger-sized cloud one thread costs little.
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        mesh, densities = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(cloud, depth=int(depth), n_threads=1)
    densities = np.asarray(densities)
    unsupported = np.zeros(len(densities), bool)
    if density_quantile > 0 and len(densities):
        unsupported |= densities < np.quantile(densities, density_quantile)
    if support_distance is None:
        support_distance = SUPPORT_SPACINGS * float(np.median(cloud.compute_nearest_neighbor_distance()))
    if np.isfinite(support_distance):
        distance, _ = cKDTree(np.asarray(cloud.points)).query(np.asarray(mesh.vertices), distance_upper_bound=support_distance)
        unsupported |= ~np.isfinite(distance)
    mesh.remove_vertices_by_mask(unsupported)
    box = cloud.get_axis_aligned_bounding_box()
    margin = _BOX_MARGIN * np.linalg.norm(box.get_extent())
    mesh = mesh.crop(o3d.geometry.AxisAlignedBoundingBox(box.min_bound - margin, box.max_bound + margin))
    if len(mesh.triangles) == 0:
        raise ValueError("Poisson reconstruction left no triangles inside the point cloud's bounding box")

    colors = np.asarray(mesh.vertex_colors) if cloud.has_colors() and mesh.has_vertex_colors() else None
    vertices, triangles, colors = _clean(np.asarray(mesh.vertices), np.asarray(mesh.triangles), colors,
                                         None if target_triangles is None else int(target_triangles))
    if len(triangles) == 0:
        raise ValueError("mesh cleaning removed every triangle (the point cloud holds no connected surface)")
    result = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(triangles))
    if colors is not None:
        result.vertex_colors = o3d.utility.Vector3dVector(np.clip(colors, 0.0, 1.0))
    result.compute_vertex_normals()
    return result


def write_mesh(path: str | Path, mesh: "o3d.geometry.TriangleMesh") -> Path:
    """Write a triangle mesh as binary PLY (float32 vertices, vertex normals and colours it has), atomically.

    Written through trimesh, so MeshLab, Open3D and trimesh read it. Refuses (``ValueError``
    naming ``path``, nothing written) a mesh without triangles or with NaN/Inf vertices.
    """
    import trimesh
    from trimesh.exchange.ply import export_ply

    path = Path(path)
    if not hasattr(mesh, "triangles"):
        raise TypeError(f"{path}: expected an open3d.geometry.TriangleMesh, got {type(mesh).__name__}")
    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    if len(faces) == 0 or len(vertices) == 0:
        raise ValueError(f"{path}: refusing to write a mesh without triangles")
    if not np.all(np.isfinite(vertices)):
        raise ValueError(f"{path}: refusing to write a mesh with NaN or Inf vertices")
    colors = None
    if mesh.has_vertex_colors():
        colors = np.round(np.clip(np.asarray(mesh.vertex_colors), 0.0, 1.0) * 255).astype(np.uint8)
    normals = np.asarray(mesh.vertex_normals) if mesh.has_vertex_normals() else None
    shaped = trimesh.Trimesh(vertices=vertices, faces=faces, vertex_normals=normals, vertex_colors=colors, process=False)
    data = export_ply(shaped, encoding="binary", vertex_normal=normals is not None)
    with atomic_path(path) as temporary:
        temporary.write_bytes(data)
    return path
