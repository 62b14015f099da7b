"""Rays through a device scene: one shadow query and one eye-ray query over the soup and the instances.

A device scene's geometry is the soup (one ``wp.Mesh``) and, for an instanced scene, the instances
(:mod:`wsoft.scene.instancing`). :func:`unoccluded` asks of a shadow ray's segment whether anything
of the scene blocks it, :func:`blocker_distance` how far along it the nearest blocker lies (a
closest-hit query, for techniques that need the blocker's distance), :func:`nearest_hit` finds the
nearest surface along an eye ray: the soup is tested first, then the instances. A kernel that
casts shadow rays takes one :class:`Occluders` (built by :func:`occluders`, once per device scene
and set of prims a light's ``collection:shadowLink`` leaves out). :func:`ray_triangle` is the
ray-triangle test Warp's own BVH queries use, for kernels that test triangles of their own.
"""

from __future__ import annotations

import warp as wp

from wsoft.scene.device import DeviceScene, shadow_surfaces
from wsoft.scene.instancing import InstancesGPU, nearest_blocker_instances, nearest_instance_hit, occluded_instances
from wsoft.scene.surfaces import Surfaces, nearest_blocker_from, nearest_from, occluded


@wp.struct
class Occluders:
    """What one light's shadow rays meet: the soup's ``wp.Mesh``, the instances, and the surfaces
    (the triangles of prims the light's ``collection:shadowLink`` leaves out are a cutout with
    nothing present, :func:`~wsoft.scene.device.shadow_surfaces`) with their cutout flag."""

    mesh: wp.uint64  # the soup's wp.Mesh
    cut: Surfaces
    has_cutouts: int  # 0: no triangle is alpha-tested
    inst: InstancesGPU  # count = 0: no instances


def occluders(ds: DeviceScene, excluded: tuple[int, ...] = ()) -> Occluders:
    """The :class:`Occluders` of ``ds`` for a light whose shadows leave out the prims ``excluded``
    (indices into the scene's prims; empty: every prim casts). Built once per set of prims."""
    key = tuple(excluded)
    if key not in ds.occluders:
        cut, has_cutouts = shadow_surfaces(ds, key)
        occ = Occluders()
        occ.mesh = ds.mesh.id
        occ.cut = cut
        occ.has_cutouts = has_cutouts
        occ.inst = ds.inst
        ds.occluders[key] = occ
    return ds.occluders[key]


@wp.func
def unoccluded(occ: Occluders, origin: wp.vec3, dir: wp.vec3, max_t: float) -> bool:
    """Is the segment origin + t*dir (``dir`` unit length), t in (0, max_t), free of every surface
    that casts (any-hit, alpha-tested through cutouts)? The soup is tested first, then the instances."""
    if occluded(occ.mesh, occ.cut, occ.has_cutouts, origin, dir, max_t):
        return False
    return not occluded_instances(occ.inst, occ.cut, occ.has_cutouts, origin, dir, max_t)


@wp.func
def blocker_distance(occ: Occluders, origin: wp.vec3, dir: wp.vec3, max_t: float) -> float:
    """:func:`unoccluded`'s segment as a closest-hit query: the distance from ``origin`` to the
    nearest surface that blocks it (alpha-tested through cutouts, through the prims the light's
    ``collection:shadowLink`` leaves out), or -1 when the segment is free. The soup is tested first,
    then the instances within the soup's hit."""
    t = nearest_blocker_from(occ.mesh, 0, occ.cut, occ.has_cutouts, origin, dir, max_t)
    reach = max_t
    if t >= 0.0:
        reach = t
    ti = nearest_blocker_instances(occ.inst, occ.cut, occ.has_cutouts, origin, dir, reach)
    if ti >= 0.0:
        t = ti
    return t


@wp.func
def nearest_hit(mesh: wp.uint64, cut: Surfaces, has_cutouts: int, inst: InstancesGPU, start: wp.vec3, dir: wp.vec3, reach: float,
                travelled: float):
    """The nearest surface an eye ray meets along start + s*dir (``dir`` unit length), s in (0, reach),
    in the soup's ``mesh`` and then among the instances of ``inst`` (within the soup's hit):
    back faces of single-sided meshes skipped, alpha-tested through cutouts. Returns (found 0/1,
    ``travelled`` plus the distance to the hit, triangle (combined index), u, v, the triangle's
    unit geometric normal in the world, the hit point in the world from the triangle's corners, and
    the scale its rounding is a few ulps of: what :func:`~wsoft.scene.offsets.ray_offset` takes)."""
    found, dist, face, bu, bv, n, p, scale = nearest_from(mesh, 0, cut, has_cutouts, start, dir, reach, travelled)
    if inst.count > 0:
        within = reach
        if found == 1:
            within = dist - travelled
        ifound, it, iface, iu, iv, inrm, ip, iscale = nearest_instance_hit(inst, cut, has_cutouts, start, dir, within)
        if ifound == 1:
            found = 1
            face = iface
            bu = iu
            bv = iv
            n = inrm
            p = ip
            scale = iscale
            dist = travelled + it
    return found, dist, face, bu, bv, n, p, scale


@wp.func_native(
    """float t, u, v, sign;
    wp::vec3 nrm;
    if (wp::intersect_ray_tri_woop(o, d, a, b, c, t, u, v, sign, &nrm))
        return wp::vec4(1.0f, t, u, v);
    return wp::vec4(0.0f, 0.0f, 0.0f, 0.0f);"""
)
def ray_triangle(o: wp.vec3, d: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> wp.vec4:
    """Warp's watertight ray-triangle test: (hit, t, u, v), ``u, v`` weights of ``a, b``."""
    ...
