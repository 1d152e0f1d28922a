"""Seeds from a mesh: spot centres sampled on (Surface) or inside (Inside) a Mesh object, for
licvdb's explicit spots (recipe ``input: {"type": "spots", "seeds": PATH}``).

The mesh is read evaluated (modifiers applied) in Blender's world space (``matrix_world``):

* Surface: points spread over the triangles, about ``seed_spacing`` apart: each triangle gets
  area/spacing² points on average (rounded at random), uniformly placed; deterministic
  (``random.Random(settings.seed)``), O(N).
* Inside: the points of a regular lattice of pitch ``seed_spacing`` (aligned to world multiples of
  the pitch) inside the closed mesh: one ray per lattice row along +x, counting crossings. An open
  mesh, or one with no lattice point inside (flat, or smaller than the pitch), is refused.

The spacing is in world units (Blender units), not output voxels: the bake's voxel size is not
known before licvdb reads the field. The points are then mapped into the field's coordinates
(``to_field``: identity for a flow file, the inverse of the source volume's or fluid domain's
placement) and written as text, ``x y z`` per line, beside the bake's output (OUT.seeds.txt).
"""

import math
import random

from mathutils import Vector
from mathutils.bvhtree import BVHTree

#: The most points a seed mesh may give (licvdb itself accepts up to 50 M).
MAX_POINTS = 2_000_000


class SeedError(Exception):
    """The seed mesh cannot give seeds; the message says what to do."""


def world_triangles(context, obj):
    """(vertices [Vector], triangles [(i, j, k)], open edge count) of ``obj``'s evaluated mesh in world space."""
    depsgraph = context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    try:
        mw = ev.matrix_world.copy()
        verts = [mw @ v.co for v in mesh.vertices]
        mesh.calc_loop_triangles()
        tris = [tuple(t.vertices) for t in mesh.loop_triangles]
        faces_per_edge = {}
        for p in mesh.polygons:
            for key in p.edge_keys:
                faces_per_edge[key] = faces_per_edge.get(key, 0) + 1
        open_edges = sum(1 for n in faces_per_edge.values() if n != 2)
    finally:
        ev.to_mesh_clear()
    return verts, tris, open_edges


def _too_many(n, obj, spacing):
    return SeedError(f"seed object {obj.name} would give about {n:,} points at spacing {spacing:g}, more than "
                     f"{MAX_POINTS:,}: increase the Seed spacing")


def surface_points(verts, tris, spacing: float, seed: int, obj=None) -> list:
    """Points on the triangles, area/spacing² per triangle on average (deterministic for ``seed``)."""
    areas = []
    for i, j, k in tris:
        a, b, c = verts[i], verts[j], verts[k]
        areas.append(0.5 * (b - a).cross(c - a).length)
    expected = sum(areas) / (spacing * spacing)
    if expected > MAX_POINTS:
        raise _too_many(int(expected), obj, spacing)
    rng = random.Random(seed)
    out = []
    for (i, j, k), area in zip(tris, areas):
        m = area / (spacing * spacing)
        n = int(m) + (1 if rng.random() < m - int(m) else 0)
        a, b, c = verts[i], verts[j], verts[k]
        for _ in range(n):
            u, v = rng.random(), rng.random()
            if u + v > 1.0:
                u, v = 1.0 - u, 1.0 - v
            out.append(a + u * (b - a) + v * (c - a))
    return out


def inside_points(verts, tris, spacing: float, obj=None) -> list:
    """Lattice points (multiples of ``spacing``) inside the closed triangle mesh."""
    if not tris:
        return []
    bvh = BVHTree.FromPolygons(verts, tris, all_triangles=True)
    lo = Vector([min(v[a] for v in verts) for a in range(3)])
    hi = Vector([max(v[a] for v in verts) for a in range(3)])
    i0 = [math.ceil(lo[a] / spacing) for a in range(3)]
    i1 = [math.floor(hi[a] / spacing) for a in range(3)]
    if any(i1[a] < i0[a] for a in range(3)):
        return []
    estimate = (i1[0] - i0[0] + 1) * (i1[1] - i0[1] + 1) * (i1[2] - i0[2] + 1)
    x_start = lo.x - spacing
    length = (hi.x - lo.x) + 2 * spacing
    # A tiny offset of the rays off the lattice rows keeps them off edges and vertices that lie
    # exactly on a row (a crossing counted twice); the points themselves stay on the lattice.
    dy, dz = 1.234567e-6 * spacing, 2.345678e-6 * spacing
    eps = 1e-7 * max(spacing, length)
    out = []
    for iy in range(i0[1], i1[1] + 1):
        for iz in range(i0[2], i1[2] + 1):
            y, z = iy * spacing, iz * spacing
            origin = Vector((x_start, y + dy, z + dz))
            crossings = []
            travelled = 0.0
            while travelled < length:
                loc, _normal, _index, dist = bvh.ray_cast(origin, Vector((1.0, 0.0, 0.0)), length - travelled)
                if loc is None:
                    break
                crossings.append(loc.x)
                origin = Vector((loc.x + eps, origin.y, origin.z))
                travelled = origin.x - x_start
            for enter, leave in zip(crossings[0::2], crossings[1::2]):
                for ix in range(max(i0[0], math.ceil(enter / spacing)), min(i1[0], math.floor(leave / spacing)) + 1):
                    out.append(Vector((ix * spacing, y, z)))
                if len(out) > MAX_POINTS:
                    raise _too_many(max(len(out), estimate), obj, spacing)
    return out


def sample(context, obj, mode: str, spacing: float, seed: int) -> list:
    """World-space seed points of the Mesh object ``obj`` (``mode`` SURFACE or INSIDE). Raises SeedError."""
    if obj is None or obj.type != "MESH":
        raise SeedError("the seed object must be a Mesh object")
    if spacing <= 0:
        raise SeedError("Seed spacing must be > 0")
    verts, tris, open_edges = world_triangles(context, obj)
    if not tris:
        raise SeedError(f"seed object {obj.name} has no faces: give it a surface, or clear Seed object")
    if mode == "SURFACE":
        pts = surface_points(verts, tris, spacing, seed, obj)
        if not pts:
            raise SeedError(f"seed object {obj.name} is too small for Seed spacing {spacing:g}: no point on it; "
                            "decrease the spacing")
        return pts
    if open_edges:
        raise SeedError(f"seed object {obj.name} is not a closed mesh ({open_edges} open edges): Inside needs a "
                        "closed surface; use Surface, or close the mesh")
    pts = inside_points(verts, tris, spacing, obj)
    if not pts:
        raise SeedError(f"no lattice point of spacing {spacing:g} lies inside seed object {obj.name} (flat, open or "
                        "smaller than the spacing): decrease the Seed spacing, or use Surface")
    return pts


def write_seeds(path: str, points, to_field=None) -> int:
    """Write ``points`` (mapped by the 4×4 ``to_field`` if given) as text ``x y z`` lines; returns the count."""
    with open(path, "w", encoding="utf-8") as f:
        f.write(f"# licvdb seeds from a mesh: {len(points)} points, x y z in the field's world coordinates\n")
        for p in points:
            q = to_field @ p if to_field is not None else p
            f.write(f"{q[0]:.9g} {q[1]:.9g} {q[2]:.9g}\n")
    return len(points)


def read_seeds(path: str) -> list:
    """The points of a seeds text file (for tests and inspection)."""
    out = []
    with open(path, encoding="utf-8") as f:
        for line in f:
            line = line.split("#", 1)[0].strip()
            if line:
                out.append(tuple(float(x) for x in line.split()))
    return out


def apply(context, settings, recipe: dict, base: str, to_field=None, unsteady: str = "") -> str:
    """If the bake settings name a seed object: sample it, write ``BASE.seeds.txt`` and make the
    recipe's input those spots; returns the seeds path ("" without a seed object). ``unsteady``
    describes an unsteady sequence being planned (licvdb refuses seeds there). Raises SeedError."""
    obj = settings.seed_object
    if obj is None:
        return ""
    if unsteady:
        raise SeedError(f"{unsteady} is baked as one unsteady sequence, which cannot take seeds from a mesh (licvdb "
                        f"places new spots by its distribution): clear Seed object ({obj.name}) or bake one frame")
    points = sample(context, obj, settings.seed_mode, settings.seed_spacing, settings.seed)
    path = f"{base}.seeds.txt"
    write_seeds(path, points, to_field)
    inp = recipe["input"]
    inp["type"] = "spots"
    inp["seeds"] = path
    inp["radii"] = [settings.spot_radius]
    inp.pop("spacing", None)
    inp.pop("distribution", None)
    return path


def seed_object_poll(_self, obj):
    return obj.type == "MESH"

