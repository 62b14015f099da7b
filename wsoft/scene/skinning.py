"""Skinning kernels: UsdSkel's linear blend and dual-quaternion skinning of a mesh's points.

Both follow UsdSkel's own definitions (``UsdSkelSkinPoints``), so a mesh skinned here matches
``UsdSkel.SkinningQuery.ComputeSkinnedPoints`` to float rounding:

* every point is first taken to the skeleton's space by the binding's ``geomBindTransform``;
* **classicLinear**: the weighted sum of the point moved by each influencing joint's skinning
  transform;
* **dualQuaternion**: each joint's transform is factored (``GfMatrix4d::Factor``) into a rotation
  and translation, held as a unit dual quaternion, and a residual scale and shear; the point is
  scaled by the weighted sum of the residuals (linear blending, only where some joint has one),
  then moved by the normalised weighted sum of the joints' dual quaternions, each turned to the
  hemisphere of the point's heaviest joint's rotation.

Joint indices out of range are a loader error (:mod:`wsoft.scene.usd_skel` checks them before a
launch); a weight of zero skips its joint. Matrices here are in the column-vector convention
(``p' = M p``), USD's transposed.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from wsoft.parallel import launch_chunked


@wp.func
def dual_quat_point(r: wp.quat, d: wp.quat, p: wp.vec3) -> wp.vec3:
    """``p`` moved by the unit dual quaternion ``(r, d)`` (``d`` orthogonal to ``r``): the rotation
    ``r``, then the translation ``2 (d r*)``."""
    t = wp.mul(d, wp.quat_inverse(r))
    return wp.quat_rotate(r, p) + 2.0 * wp.vec3(t[0], t[1], t[2])


@wp.kernel
def skin_points_linear(offset: int, points: wp.array[wp.vec3], geom_bind: wp.mat44, joints: wp.array[wp.mat44],
                       indices: wp.array[wp.int32], weights: wp.array[wp.float32], per_point: int,
                       # outputs
                       skinned: wp.array[wp.vec3]):
    i = wp.tid() + offset
    p0 = wp.transform_point(geom_bind, points[i])
    p = wp.vec3(0.0)
    for k in range(per_point):
        w = weights[i * per_point + k]
        if w != 0.0:
            p += w * wp.transform_point(joints[indices[i * per_point + k]], p0)
    skinned[i] = p


@wp.kernel
def skin_points_dual_quaternion(offset: int, points: wp.array[wp.vec3], geom_bind: wp.mat44, real: wp.array[wp.quat],
                                dual: wp.array[wp.quat], scales: wp.array[wp.mat33], has_scale: int,
                                indices: wp.array[wp.int32], weights: wp.array[wp.float32], per_point: int,
                                # outputs
                                skinned: wp.array[wp.vec3]):
    i = wp.tid() + offset
    p0 = wp.transform_point(geom_bind, points[i])
    # the heaviest joint's rotation: every joint's dual quaternion is turned to its hemisphere
    pivot = int(-1)
    heaviest = float(-1.0)
    for k in range(per_point):
        w = weights[i * per_point + k]
        if pivot < 0 or heaviest < w:
            heaviest = w
            pivot = indices[i * per_point + k]
    rp = wp.quat(0.0, 0.0, 0.0, 0.0)
    if pivot >= 0:
        rp = real[pivot]
    sr = wp.quat(0.0, 0.0, 0.0, 0.0)
    sd = wp.quat(0.0, 0.0, 0.0, 0.0)
    scaled = wp.vec3(0.0)
    for k in range(per_point):
        w = weights[i * per_point + k]
        if w != 0.0:
            j = indices[i * per_point + k]
            if has_scale != 0:
                scaled += w * (scales[j] * p0)
            r = real[j]
            if wp.dot(r, rp) < 0.0:
                w = -w
            sr += w * r
            sd += w * dual[j]
    if has_scale == 0:
        scaled = p0
    n = wp.length(sr)
    if n < 1.0e-10:  # GfDualQuat's normalisation of a vanishing rotation: the identity
        skinned[i] = scaled
    else:
        r = sr / n
        d = sd / n - r * (wp.dot(sr, sd) / (n * n))
        skinned[i] = dual_quat_point(r, d, scaled)


def dual_quaternions(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """UsdSkel's factoring of ``[J, 4, 4]`` skinning transforms (column-vector convention) for
    dual-quaternion skinning: per joint the rotation quaternion ``[J, 4]`` (x, y, z, w), the dual
    part ``[J, 4]``, the residual scale and shear ``[J, 3, 3]`` (column-vector convention), and
    whether any residual differs from the identity by more than 1e-6. A transform that does not
    factor gets a zero dual quaternion and no residual, as UsdSkel gives it."""
    from pxr import Gf

    n = len(joints)
    real, dual, scales = np.zeros((n, 4)), np.zeros((n, 4)), np.tile(np.eye(3), (n, 1, 1))
    has_scale = False
    for j in range(n):
        m = Gf.Matrix4d(*np.asarray(joints[j], np.float64).T.ravel().tolist())  # USD's row-vector matrix
        ok, _, _, u, t, _ = m.Factor()
        if not ok:
            continue
        u.Orthonormalize()
        dq = Gf.DualQuatd(u.ExtractRotationQuat(), t)
        r, d = dq.GetReal(), dq.GetDual()
        real[j] = (*r.GetImaginary(), r.GetReal())
        dual[j] = (*d.GetImaginary(), d.GetReal())
        rest = (m * (u * Gf.Matrix4d(1.0).SetTranslate(t)).GetInverse()).ExtractRotationMatrix()
        s = np.array(rest, np.float64).T  # column-vector convention
        scales[j] = s
        has_scale |= bool(np.any(np.abs(s - np.eye(3)) > 1e-6))
    return real, dual, scales, has_scale


class JointSet:
    """One skeleton's joints at one time code, on ``device``: the skinning transforms ``[J, 4, 4]``
    (column-vector convention) and, made on first use, their dual quaternions
    (:func:`dual_quaternions`). Every mesh the skeleton deforms shares them."""

    def __init__(self, joints: np.ndarray, device: str = "cpu"):
        self.joints = np.asarray(joints, np.float64)
        self.device = device
        self._linear = None
        self._dual = None

    def linear(self):
        if self._linear is None:
            self._linear = wp.array(np.ascontiguousarray(self.joints, np.float32), dtype=wp.mat44, device=self.device)
        return self._linear

    def dual(self):
        if self._dual is None:
            real, dual, scales, has_scale = dual_quaternions(self.joints)
            self._dual = (wp.array(real.astype(np.float32), dtype=wp.quat, device=self.device),
                          wp.array(dual.astype(np.float32), dtype=wp.quat, device=self.device),
                          wp.array(scales.astype(np.float32), dtype=wp.mat33, device=self.device), int(has_scale))
        return self._dual


SMALL = 4096  # points: a mesh this small is skinned in one launch (chunking costs more than it saves)


def skin_points(points: np.ndarray, geom_bind: np.ndarray, joints: JointSet, indices: np.ndarray, weights: np.ndarray,
                per_point: int, method: str) -> np.ndarray:
    """``[N, 3]`` points skinned into the skeleton's space by ``method`` (``classicLinear`` or
    ``dualQuaternion``): ``geom_bind`` ``[4, 4]`` in the column-vector convention, ``joints`` the
    skeleton's (in the mesh's joint order), ``indices``/``weights`` ``[N * per_point]`` (varying
    influences, indices already in range). Float32 points, as UsdSkel skins them."""
    n = len(points)
    if n == 0:
        return np.zeros((0, 3), np.float32)
    device = joints.device
    out = wp.empty(n, dtype=wp.vec3, device=device)
    pts = wp.array(np.ascontiguousarray(points, np.float32), dtype=wp.vec3, device=device)
    idx = wp.array(np.ascontiguousarray(indices, np.int32), dtype=wp.int32, device=device)
    wts = wp.array(np.ascontiguousarray(weights, np.float32), dtype=wp.float32, device=device)
    gb = wp.mat44(*np.asarray(geom_bind, np.float32).ravel())
    if method == "dualQuaternion":
        real, dual, scales, has_scale = joints.dual()
        kernel, inputs = skin_points_dual_quaternion, [pts, gb, real, dual, scales, has_scale, idx, wts, int(per_point)]
    else:
        kernel, inputs = skin_points_linear, [pts, gb, joints.linear(), idx, wts, int(per_point)]
    if n <= SMALL:
        wp.launch(kernel, dim=n, inputs=[0, *inputs], outputs=[out], device=device)
    else:
        launch_chunked(kernel, n, inputs=inputs, outputs=[out], device=device)
    return out.numpy()
