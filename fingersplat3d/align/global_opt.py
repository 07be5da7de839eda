"""Global alignment of N views (the paper's eq. 3), jointly over poses, focal, scales and depth.

Unknowns, optimised together in torch (float64):

* a rigid ``cam_to_world`` per view (view ``root`` fixed: the gauge),
* one shared focal length (or one per view), principal point at the image centre,
* per view a depth model on top of the backend's own-frame pointmap depth ``z_v``:
  ``depth_v(p) = s_v * (m_v + alpha_v * (z_v(p) - m_v) + relief_v * poly_v(p))`` where ``m_v`` is
  the median depth, ``alpha_v`` scales the relief (a wrong cross-section makes it too flat or too
  deep), and ``poly_v`` is a low-degree polynomial in normalised pixel coordinates (a smooth
  correction the backend's pointmap may lack). ``s_0 = 1`` fixes the overall scale.

Objective, over the inlier correspondences ``(p in a, q in b, weight w)`` of every registered
pair: confidence-weighted 3D distance between the two views' world points (eq. 3, relative to the
scene size) plus the symmetric reprojection error in pixels (robust, Cauchy), plus weak priors
keeping ``alpha`` near 1, the polynomial small and the focal near the backend's guess.

Initialisation: a maximum spanning tree of the pairs weighted by inlier counts, chaining each
pair's similarity (``b_to_a``) from the root, as in DUSt3R's ``init='mst'``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import torch

__all__ = ["PairCorrespondences", "GlobalAlignConfig", "GlobalAlignment", "global_align", "spanning_tree",
           "polynomial_basis"]


@dataclass(frozen=True, eq=False)
class PairCorrespondences:
    """Inlier correspondences of one registered pair and its initial relative similarity."""

    a: int
    b: int
    uv_a: np.ndarray  # [M, 2] pixels in view a
    uv_b: np.ndarray  # [M, 2] pixels in view b
    weight: np.ndarray  # [M] >= 0
    b_to_a: np.ndarray  # [4, 4] similarity taking b's own-frame points into a's frame


@dataclass(frozen=True)
class GlobalAlignConfig:
    """Settings of the joint optimisation."""

    iterations: int = 300
    """Adam steps."""
    learning_rate: float = 0.01
    """Initial Adam step size (parameters are normalised to O(1)); decays with a cosine schedule."""
    polish_iterations: int = 100
    """L-BFGS iterations after Adam, for sub-pixel convergence (0 = none)."""
    shared_focal: bool = True
    """One focal length for all views (same camera), else one per view."""
    optimize_focal: bool = True
    """Let the focal move away from the backend's guess (needs >= 2 views with parallax)."""
    poly_degree: int = 2
    """Degree of the smooth per-view depth correction (0 = none)."""
    point_weight: float = 1.0
    """Weight of the 3D point distance term (relative to the scene size)."""
    reprojection_weight: float = 1.0
    """Weight of the reprojection term (pixels, Cauchy-robust)."""
    robust_px: float = 2.0
    """Cauchy scale of the reprojection residual, pixels."""
    alpha_prior: float = 0.05
    """Strength of the pull of the relief scale toward 1."""
    poly_prior: float = 0.05
    """Strength of the pull of the depth polynomial toward 0."""
    focal_prior: float = 1.0
    """Strength of the pull of log-focal toward the guess."""


@dataclass(frozen=True, eq=False)
class GlobalAlignment:
    """The aligned views: poses, focal lengths, dense depth maps and residuals."""

    cam_to_world: list[np.ndarray]  # N x [4, 4] rigid
    focals: list[float]
    depths: list[np.ndarray]  # N x [H, W] float32, NaN where the pointmap had no point
    relief_scale: list[float]
    scales: list[float]
    residual_px: float  # weighted median reprojection error over all correspondences
    residual_rel3d: float  # weighted median 3D distance / scene size
    tree: list[tuple[int, int]]
    aligned: list[bool]  # views reached by the spanning tree
    loss_history: list[float] = field(default_factory=list)

    @property
    def world_to_cam(self) -> list[np.ndarray]:
        return [np.linalg.inv(pose) for pose in self.cam_to_world]


def spanning_tree(n_views: int, pairs: Sequence[PairCorrespondences], root: int | None = None) -> tuple[int, list[tuple[int, int]]]:
    """Maximum spanning tree by total correspondence weight; returns the root and parent→child edges."""
    strength = np.zeros((n_views, n_views))
    for pair in pairs:
        strength[pair.a, pair.b] += float(np.sum(pair.weight))
        strength[pair.b, pair.a] += float(np.sum(pair.weight))
    if root is None:
        root = int(np.argmax(strength.sum(1))) if strength.any() else 0
    reached, edges = {root}, []
    while True:
        best = None
        for parent in reached:
            for child in range(n_views):
                if child not in reached and strength[parent, child] > 0:
                    if best is None or strength[parent, child] > strength[best[0], best[1]]:
                        best = (parent, child)
        if best is None:
            return root, edges
        edges.append(best)
        reached.add(best[1])


def polynomial_basis(uv: np.ndarray, size: tuple[int, int], degree: int) -> np.ndarray:
    """Monomials ``x^i y^j`` (1 <= i + j <= degree) of pixel coordinates normalised to [-1, 1]; ``[M, K]``."""
    width, height = size
    x = 2.0 * uv[..., 0] / max(width - 1, 1) - 1.0
    y = 2.0 * uv[..., 1] / max(height - 1, 1) - 1.0
    terms = [x ** i * y ** (total - i) for total in range(1, degree + 1) for i in range(total + 1)]
    return np.stack(terms, axis=-1) if terms else np.zeros(uv.shape[:-1] + (0,))


def _bilinear(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    height, width = image.shape
    u = np.clip(uv[:, 0], 0, width - 1.000001)
    v = np.clip(uv[:, 1], 0, height - 1.000001)
    u0, v0 = np.floor(u).astype(int), np.floor(v).astype(int)
    fu, fv = u - u0, v - v0
    patch = [image[v0, u0], image[v0, u0 + 1], image[v0 + 1, u0], image[v0 + 1, u0 + 1]]
    value = (1 - fv) * ((1 - fu) * patch[0] + fu * patch[1]) + fv * ((1 - fu) * patch[2] + fu * patch[3])
    nearest = image[np.round(v).astype(int), np.round(u).astype(int)]
    return np.where(np.isfinite(value), value, nearest)


def axis_angle_to_matrix(omega: torch.Tensor) -> torch.Tensor:
    """Batched Rodrigues ``[..., 3] -> [..., 3, 3]``, with finite values and gradients at zero."""
    theta2 = (omega * omega).sum(-1, keepdim=True)[..., None]  # [..., 1, 1]
    small = theta2 < 1e-12
    safe = torch.where(small, torch.ones_like(theta2), theta2)  # keeps sqrt's gradient finite
    theta = torch.sqrt(safe)
    a = torch.where(small, 1.0 - theta2 / 6.0, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24.0, (1.0 - torch.cos(theta)) / safe)
    x, y, z = omega[..., 0], omega[..., 1], omega[..., 2]
    zero = torch.zeros_like(x)
    cross = torch.stack([torch.stack([zero, -z, y], -1), torch.stack([z, zero, -x], -1),
                         torch.stack([-y, x, zero], -1)], -2)
    eye = torch.eye(3, dtype=omega.dtype, device=omega.device).expand(cross.shape)
    return eye + a * cross + b * (cross @ cross)


def _initial_poses(n_views: int, root: int, tree: list[tuple[int, int]],
                   pairs: Sequence[PairCorrespondences]) -> tuple[list[np.ndarray], list[float]]:
    """Chain pair similarities along the tree: rigid cam_to_world and a scale per view."""
    relative = {}
    for pair in pairs:
        relative[(pair.a, pair.b)] = pair.b_to_a
        relative[(pair.b, pair.a)] = np.linalg.inv(pair.b_to_a)
    similarity = {root: np.eye(4)}
    for parent, child in tree:
        similarity[child] = similarity[parent] @ relative[(parent, child)]
    poses, scales = [], []
    for view in range(n_views):
        matrix = similarity.get(view, np.eye(4))
        scale = float(np.cbrt(abs(np.linalg.det(matrix[:3, :3]))))
        pose = np.eye(4)
        u, _, vt = np.linalg.svd(matrix[:3, :3] / scale)
        pose[:3, :3] = u @ np.diag([1, 1, np.sign(np.linalg.det(u @ vt))]) @ vt
        pose[:3, 3] = matrix[:3, 3]
        poses.append(pose)
        scales.append(scale)
    return poses, scales


def global_align(depths: Sequence[np.ndarray], focal_guess: float | Sequence[float],
                 pairs: Sequence[PairCorrespondences], config: GlobalAlignConfig = GlobalAlignConfig(),
                 root: int | None = None) -> GlobalAlignment:
    """Align views given own-frame pointmap depths ``depths[v] [H, W]`` and pair correspondences.

    ``focal_guess`` is the focal (pixels) the pointmaps were made with (one, or one per view).
    Views the spanning tree does not reach keep an identity pose and are marked not aligned.
    """
    n_views = len(depths)
    sizes = [(d.shape[1], d.shape[0]) for d in depths]
    guesses = np.broadcast_to(np.asarray(focal_guess, np.float64), (n_views,)).copy()
    root, tree = spanning_tree(n_views, pairs, root)
    aligned = [False] * n_views
    aligned[root] = True
    for _, child in tree:
        aligned[child] = True
    poses0, scales0 = _initial_poses(n_views, root, tree, pairs)
    medians = [float(np.nanmedian(d)) if np.isfinite(d).any() else 1.0 for d in depths]
    reliefs = [max(float(np.nanpercentile(np.abs(d - m), 90)) if np.isfinite(d).any() else 0.0, 1e-6 * abs(m) + 1e-12)
               for d, m in zip(depths, medians)]
    scene = float(np.median([m * s for m, s in zip(medians, scales0)]))  # typical depth: the length unit
    used = [p for p in pairs if aligned[p.a] and aligned[p.b] and len(p.weight) > 0]

    dtype = torch.float64
    # All correspondences of all pairs in flat arrays, with the pointmap depth and basis at each pixel.
    view_a, view_b, uv_a, uv_b, z_a, z_b, basis_a, basis_b, weight = ([] for _ in range(9))
    for pair in used:
        za, zb = _bilinear(depths[pair.a], pair.uv_a), _bilinear(depths[pair.b], pair.uv_b)
        keep = np.isfinite(za) & np.isfinite(zb) & np.all(np.isfinite(pair.uv_a), 1) & np.all(np.isfinite(pair.uv_b), 1)
        if not keep.any():
            continue
        w = pair.weight[keep]
        view_a.append(np.full(keep.sum(), pair.a))
        view_b.append(np.full(keep.sum(), pair.b))
        uv_a.append(pair.uv_a[keep])
        uv_b.append(pair.uv_b[keep])
        z_a.append(za[keep])
        z_b.append(zb[keep])
        basis_a.append(polynomial_basis(pair.uv_a[keep], sizes[pair.a], config.poly_degree))
        basis_b.append(polynomial_basis(pair.uv_b[keep], sizes[pair.b], config.poly_degree))
        weight.append(w / max(float(np.sum(w)), 1e-12))  # every pair counts the same
    has_data = bool(weight)

    def tensor(chunks, dims):
        return torch.tensor(np.concatenate(chunks) if chunks else np.zeros((0,) + dims), dtype=dtype)

    n_terms = polynomial_basis(np.zeros((1, 2)), (2, 2), config.poly_degree).shape[1]
    va = torch.tensor(np.concatenate(view_a) if view_a else np.zeros(0, int), dtype=torch.long)
    vb = torch.tensor(np.concatenate(view_b) if view_b else np.zeros(0, int), dtype=torch.long)
    uva, uvb = tensor(uv_a, (2,)), tensor(uv_b, (2,))
    za_t, zb_t = tensor(z_a, ()), tensor(z_b, ())
    ba_t, bb_t = tensor(basis_a, (n_terms,)), tensor(basis_b, (n_terms,))
    w_t = tensor(weight, ())
    w_t = w_t / w_t.sum().clamp_min(1e-12)

    omega = torch.zeros((n_views, 3), dtype=dtype, requires_grad=True)
    translation = torch.tensor(np.stack([p[:3, 3] for p in poses0]) / scene, dtype=dtype, requires_grad=True)
    base_rotation = torch.tensor(np.stack([p[:3, :3] for p in poses0]), dtype=dtype)
    log_scale0 = torch.tensor(np.log(scales0), dtype=dtype)
    log_scale = log_scale0.clone().requires_grad_(True)
    log_alpha = torch.zeros(n_views, dtype=dtype, requires_grad=True)
    poly = torch.zeros((n_views, n_terms), dtype=dtype, requires_grad=True)
    guess = guesses if not config.shared_focal else np.full(n_views, np.exp(np.mean(np.log(guesses))))
    log_focal_guess = torch.tensor(np.log(guess), dtype=dtype)
    log_focal = log_focal_guess.clone().requires_grad_(config.optimize_focal)
    medians_t = torch.tensor(medians, dtype=dtype)
    reliefs_t = torch.tensor(reliefs, dtype=dtype)
    centres = torch.tensor([[(w - 1) / 2.0, (h - 1) / 2.0] for w, h in sizes], dtype=dtype)
    free = torch.tensor([float(aligned[v] and v != root) for v in range(n_views)], dtype=dtype)

    def current():
        rotations = axis_angle_to_matrix(omega * free[:, None]) @ base_rotation
        scale = torch.exp(log_scale * free + log_scale0 * (1 - free))
        focal = torch.exp(log_focal.mean().expand(n_views) if config.shared_focal else log_focal)
        return rotations, scale, focal

    def world_points(view, uv, z, basis, rotations, scale, focal):
        relief = (basis * poly[view]).sum(-1) if n_terms else 0.0
        depth = scale[view] * (medians_t[view] + torch.exp(log_alpha[view]) * (z - medians_t[view])
                               + reliefs_t[view] * relief) / scene
        rays = torch.cat([(uv - centres[view]) / focal[view][:, None], torch.ones_like(uv[:, :1])], dim=1)
        return torch.einsum("nij,nj->ni", rotations[view], depth[:, None] * rays) + translation[view] * free[view][:, None] \
            + translation[view].detach() * (1 - free[view])[:, None]

    def project(view, points, rotations, focal):
        cam = torch.einsum("nji,nj->ni", rotations[view], points - translation[view])
        z = cam[:, 2].clamp_min(1e-9)
        return cam[:, :2] / z[:, None] * focal[view][:, None] + centres[view]

    def terms():
        rotations, scale, focal = current()
        xa = world_points(va, uva, za_t, ba_t, rotations, scale, focal)
        xb = world_points(vb, uvb, zb_t, bb_t, rotations, scale, focal)
        pa = project(vb, xa, rotations, focal)
        pb = project(va, xb, rotations, focal)
        return xa, xb, pa, pb, rotations, scale, focal

    def objective():
        xa, xb, pa, pb, _, _, _ = terms()
        point_term = (w_t * (xa - xb).norm(dim=1)).sum()
        r2 = ((pa - uvb) ** 2).sum(1) + ((pb - uva) ** 2).sum(1)
        reproj = (w_t * torch.log1p(r2 / config.robust_px ** 2)).sum()
        total = config.point_weight * point_term + config.reprojection_weight * reproj
        total = total + config.alpha_prior * (log_alpha ** 2).sum() + config.poly_prior * (poly ** 2).sum()
        return total + config.focal_prior * ((log_focal - log_focal_guess) ** 2).sum()

    params = [omega, translation, log_scale, log_alpha, poly] + ([log_focal] if config.optimize_focal else [])
    history = []
    if has_data:
        # Adam with a cosine-decayed step finds the basin robustly (DUSt3R's schedule); its steps are
        # ~learning_rate in every parameter, far coarser than a pixel, so L-BFGS then converges precisely.
        optimizer = torch.optim.Adam(params, lr=config.learning_rate)
        schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, max(config.iterations, 1), eta_min=1e-5)
        for _ in range(config.iterations):
            optimizer.zero_grad()
            loss = objective()
            loss.backward()
            optimizer.step()
            schedule.step()
            history.append(float(loss.detach()))
        polish = torch.optim.LBFGS(params, lr=1.0, max_iter=config.polish_iterations, tolerance_grad=1e-12,
                                   tolerance_change=1e-15, history_size=20, line_search_fn="strong_wolfe")

        def closure():
            polish.zero_grad()
            loss = objective()
            loss.backward()
            return loss

        if config.polish_iterations > 0:
            polish.step(closure)
            history.append(float(objective().detach()))
    with torch.no_grad():
        xa, xb, pa, pb, rotations, scale, focal = terms()
        if has_data:
            err_px = torch.cat([(pa - uvb).norm(dim=1), (pb - uva).norm(dim=1)]).numpy()
            residual_px = _weighted_median(err_px, np.concatenate([w_t.numpy()] * 2))
            residual_3d = _weighted_median((xa - xb).norm(dim=1).numpy(), w_t.numpy())
        else:
            residual_px = residual_3d = float("nan")
        poses, out_depths = [], []
        for view in range(n_views):
            pose = np.eye(4)
            pose[:3, :3] = rotations[view].numpy()
            pose[:3, 3] = translation[view].numpy()
            poses.append(pose)
            height, width = depths[view].shape
            grid = np.stack(np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64)), -1)
            basis = polynomial_basis(grid.reshape(-1, 2), sizes[view], config.poly_degree)
            correction = (basis @ poly[view].numpy()).reshape(height, width) if n_terms else 0.0
            alpha = float(torch.exp(log_alpha[view]))
            dense = float(scale[view]) * (medians[view] + alpha * (depths[view] - medians[view]) + reliefs[view] * correction) / scene
            out_depths.append(dense.astype(np.float32))
        focals = [float(f) for f in focal]
    return GlobalAlignment(poses, focals, out_depths, [float(torch.exp(a)) for a in log_alpha.detach()],
                           [float(s) for s in scale], residual_px, residual_3d, tree, aligned, history)


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    if cumulative[-1] <= 0:
        return float(np.median(values))
    return float(values[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])
