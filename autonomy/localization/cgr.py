"""Corrective Gradient Refinement (CGR) localization on a vector map (BV2012, IV-C).

A particle filter over (x, y, theta). Each frame (IV-C, steps 1-4):

1. the particles move through the motion model of an omnidirectional base driven by
   odometry increments: the first-stage proposal q0;
2. each sample is refined in r iterations along the gradient of the observation
   log-likelihood (:func:`autonomy.localization.observation.refine_all_m`) times a Gaussian prior
   around the sample's first-stage pose (:meth:`CGRLocalizer.prior_info`, ours):
   q1 .. qr, within a trust region of its first-stage pose (ours), on correspondences found within a gate that
   widens with the belief's spread (:meth:`CGRLocalizer.gate`, ours), and checked
   where it led: points whose line changes there are dropped (``consistent_fraction``,
   ours), only along the pose directions the points pin down (the degeneracy-aware
   update of Zhang and Singh, ICRA 2016; :attr:`CGRConfig.degeneracy_max_gain`), and
   with each point weighed by its distance to its line at the proposal mean (robust
   reweighting, :attr:`CGRConfig.robust_scale`, ours);
3. an acceptance test chooses, per sample, between its refined and its first-stage
   version: the refined one is kept with probability min(1, p(y|x_r) N(x_r) / p(y|x_0)),
   N the refinement's prior around the first-stage pose (ours; 1 there, and 1 everywhere
   without the prior);
4. samples are weighted by their observation likelihood and resampled (low variance).

With r = 0 this is plain Monte Carlo localization (MCL), kept as a baseline. The pose
estimate is the mean position and the circular-mean heading, with their spread.

Motion noise (the original code, docs/architecture.md): for an increment of translation tr and
rotation rot, the translation noise is alpha3 * tr per axis and the rotation noise
alpha1 * |rot| + alpha2 * tr. Degenerate frames (too few usable points, all weights 0 or
NaN) skip the observation: the filter goes on on odometry alone.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from autonomy.common.errors import InputError, require_int, require_non_negative, require_positive
from autonomy.common.geometry import points_from_frame, wrap_angles
from autonomy.localization.observation import (
    ObservationConfig,
    correspond,
    line_frames,
    moments,
    moments_lever,
    refine_all_m,
    robust_weights,
    trusted_directions,
)
from autonomy.maps.raycast import rays_hit

SceneLinesFn = Callable[[float, float], np.ndarray]

#: A normal distribution's standard deviation per median absolute deviation.
ROBUST_SIGMA_PER_MAD = 1.4826


@dataclass(frozen=True)
class CGRConfig:
    """CGR parameters; defaults from the paper and the original code (docs/architecture.md)."""

    n_particles: int = 20
    """Number of particles."""
    refinements: int = 6
    """r: gradient refinement iterations (point clouds); 0 = plain MCL."""
    alpha1: float = 0.1
    """Rotation noise per unit rotation."""
    alpha2_rad_per_m: float = math.radians(5.0)
    """Rotation noise per metre of translation."""
    alpha3: float = 0.1
    """Translation noise per unit translation."""
    min_translation_std_m: float = 0.001
    """Floor on the per-frame translation noise (keeps diversity when nearly still)."""
    min_rotation_std_rad: float = 0.001
    """Floor on the per-frame rotation noise."""
    mean_preserving_motion: bool = True
    """Draw each frame's motion noise with zero sample mean over the particles (moment
    matching, rescaled to keep its variance), so that the particles' mean moves exactly
    with the odometry (ours). With i.i.d. draws the mean of 20 particles wanders: its
    heading by the particle spread over sqrt(20), about a degree after 20 m without a wall
    in view, which turns into 15-25 cm beside the odometry's own few centimetres over a
    blind crossing of an atrium."""
    step_fraction: float = 0.5
    """kappa: fraction of the preconditioned gradient step taken per refinement."""
    trust_region_m: float = 0.5
    """A refinement moves the used points at most this far (rotation counted at their RMS
    range): the correspondences are fixed where it starts and hold only nearby (ours)."""
    gate_sigmas: float = 3.0
    """The correspondence gate widens to this many standard deviations of the belief at
    the points when that exceeds observation.max_distance_m (:meth:`CGRLocalizer.gate`;
    0 = the fixed gate)."""
    max_gate_m: float = 1.5
    """... up to this."""
    consistent_fraction: float = 0.5
    """Association check (ours): when the refinement moved the points more than
    observation.sigma_m, correspondences are found again at the refined mean; if fewer
    than this fraction of the used points keep their line there, the others are dropped
    and the shared refinement is redone (0 = off)."""
    prior_min_xy_m: float = 0.1
    """The refinement climbs the likelihood times a Gaussian prior around each sample's
    first-stage pose, whose spread is the belief's (position and heading) but at least
    this ... (ours; 0 with prior_min_theta_rad = 0: the likelihood alone, unbounded)."""
    prior_min_theta_rad: float = math.radians(2.0)
    """... and this: a few points of one small face cannot turn the heading by degrees
    in a frame, a wall in view still can (:func:`autonomy.localization.observation.refine_all_m`)."""
    degeneracy_max_gain: float = 8.0
    """Degeneracy-aware refinement (after Zhang and Singh, ICRA 2016): a refinement moves
    a sample only along the pose directions whose bias gain (metres of pose error per
    metre of systematic error in the points' distances to their lines) is at most this
    (:func:`autonomy.localization.observation.trusted_directions`); along the others (a corridor's
    length between walls nearly but not exactly parallel) the sample keeps its motion-
    model pose (0 = every direction)."""
    robust_scale: float = 1.0
    """Robust refinement (ours): each point's term is weighed 1 / (1 + (d / c)^2) by its
    distance d to its line at the proposal mean, c this many times the larger of
    observation.sigma_m and the belief's spread at the points (as the gate widens;
    :func:`autonomy.localization.observation.robust_weights`), then weighed again at the pose that
    fits them best on the residuals' own scale (:meth:`CGRLocalizer._reweigh`). A few
    points matched to the wrong line (seen past a pillar's corner) then cannot pull the
    belief along a corridor (0 = the squared distances of Eq. 1, one round)."""
    tail_hold_fraction: float = 0.5
    """When the samples round the mean account for at least this fraction of the frame's
    points, matched to lines or lying in front of the walls along their rays (clutter the
    map does not hold), yet none of them could be scored (the association check dropped
    the points, or fewer than observation.min_points were matched), the samples away
    from the mean are not scored either: no update this frame (ours,
    :meth:`CGRLocalizer._refine`; 0 = the tail is always scored)."""
    rescore_shared: bool = True
    """When a sample beyond share_radius_m (or share_angle_rad), refined on its own
    correspondences, scores better than every sample that shared the mean's, those are
    refined and scored again each on its own (ours; False: they keep the mean's)."""
    share_radius_m: float = 1.0
    """Particles within this distance (and share_angle_rad) of the proposal mean share its
    scene lines and correspondences; others get their own."""
    share_angle_rad: float = math.radians(20.0)
    """Heading tolerance for sharing correspondences."""
    init_std_xy_m: float = 0.05
    """Spread of the particles drawn by reset() around a pose, per axis."""
    init_std_theta_rad: float = math.radians(2.0)
    """Heading spread drawn by reset()."""

    def __post_init__(self) -> None:
        require_int(self, "cgr.", "n_particles")
        require_int(self, "cgr.", "refinements", minimum=0)
        require_non_negative(
            self, "cgr.", "alpha1", "alpha2_rad_per_m", "alpha3", "min_translation_std_m", "min_rotation_std_rad",
            "init_std_xy_m", "init_std_theta_rad", "gate_sigmas", "prior_min_xy_m", "prior_min_theta_rad",
            "degeneracy_max_gain", "robust_scale", "tail_hold_fraction",
        )
        for name in ("mean_preserving_motion", "rescore_shared"):
            if not isinstance(getattr(self, name), bool):
                raise InputError(f"cgr.{name}: expected true or false, got {getattr(self, name)!r}")
        if not 0 <= self.tail_hold_fraction <= 1:
            raise InputError(f"cgr.tail_hold_fraction: expected a number in [0, 1], got {self.tail_hold_fraction!r}")
        if not 0 <= self.consistent_fraction <= 1:
            raise InputError(f"cgr.consistent_fraction: expected a number in [0, 1], got {self.consistent_fraction!r}")
        require_positive(self, "cgr.", "max_gate_m", "trust_region_m", "step_fraction")
        if not 0 < self.step_fraction <= 1:
            raise InputError(f"cgr.step_fraction: expected a number in (0, 1], got {self.step_fraction!r}")


@dataclass(frozen=True)
class Estimate:
    """The filter's belief summary."""

    pose: np.ndarray
    """Mean x, y and circular-mean heading."""
    std_xy_m: float
    """RMS distance of the particles from the mean position."""
    std_theta_rad: float
    """Circular standard deviation of the headings."""
    cov_xy: np.ndarray
    """2 x 2 covariance of the particle positions."""


@dataclass
class UpdateStats:
    """What one update did (for reports and tests)."""

    points: int = 0
    used_points: int = 0
    accepted_refinements: int = 0
    observation: bool = False
    shared: int = 0
    dropped_points: int = 0
    """Points the association check dropped (their line changed at the refined pose)."""
    unscored_tail: int = 0
    """Particles away from the mean left unscored because those round it accounted for
    most of the frame's points but could not be scored
    (:attr:`CGRConfig.tail_hold_fraction`): no update this frame."""
    rescored: int = 0
    """Samples round the mean scored again on their own correspondences because one away
    from it outscored them (:attr:`CGRConfig.rescore_shared`)."""
    trusted_directions: int = 3
    """Pose directions the shared correspondences pin down (0-3; the refinement moves
    samples along these only, :attr:`CGRConfig.degeneracy_max_gain`)."""


class _Frame(NamedTuple):
    """One observation as the refinement reads it."""

    pts: np.ndarray
    """(n, 2) points, robot frame."""
    nrm: np.ndarray
    """(n, 2) their normals (zeros for the laser model)."""
    use_n: bool
    """Whether the normals are used (point-cloud model)."""
    cos_max: float
    """cos(theta_max): the normal-agreement test."""
    gate: float
    """Correspondence gate for this frame (:meth:`CGRLocalizer.gate`)."""
    prior_info: np.ndarray
    """1/sigma^2 (x, y, theta) of the refinement's prior (:meth:`CGRLocalizer.prior_info`)."""
    robust_m: float
    """Scale of the points' robust weights (:meth:`CGRLocalizer.robust_scale_m`; 0: none)."""


def _best(lnp0: np.ndarray, lnpr: np.ndarray) -> float:
    """The best finite log-likelihood of a set of samples, first-stage or refined
    (-inf when none is finite)."""
    v = np.concatenate([lnp0, lnpr])
    v = v[np.isfinite(v)]
    return float(v.max()) if len(v) else -math.inf


def circular_mean(theta: np.ndarray, w: np.ndarray | None = None) -> float:
    w = np.ones(len(theta)) if w is None else w
    return float(math.atan2(np.sum(w * np.sin(theta)), np.sum(w * np.cos(theta))))


def low_variance_resample(weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Indices drawn by low-variance (systematic) resampling (Thrun et al., Table 4.4)."""
    n = len(weights)
    c = np.cumsum(weights)
    c[-1] = 1.0
    u = (rng.uniform(0.0, 1.0 / n) + np.arange(n) / n)
    return np.searchsorted(c, u, side="left").clip(0, n - 1)


class CGRLocalizer:
    """CGR over a map given as a scene-lines function (location -> (M, 4) visible lines)."""

    def __init__(
        self,
        scene_lines: SceneLinesFn,
        cfg: CGRConfig = CGRConfig(),
        obs: ObservationConfig = ObservationConfig(),
        rng: np.random.Generator | None = None,
    ) -> None:
        self.scene_lines = scene_lines
        self.cfg = cfg
        self.obs = obs
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.particles = np.zeros((cfg.n_particles, 3))
        self.weights = np.full(cfg.n_particles, 1.0 / cfg.n_particles)
        self.before_refinement = self.particles.copy()
        self.after_refinement = self.particles.copy()
        """Particles after refinement and acceptance, before resampling (for viewers)."""
        self.refined_weights = self.weights.copy()
        """Their normalised importance weights (Alg. 1 line 7)."""
        self.last = UpdateStats()
        self.last_lines: np.ndarray | None = None
        """The scene lines the last update used, seen from its proposal mean (None: the
        update stopped before querying them). The stack's health check reads them instead
        of querying again a few centimetres away."""

    # -- belief ------------------------------------------------------------------------
    def reset(self, pose: np.ndarray, std_xy_m: float | None = None, std_theta_rad: float | None = None) -> None:
        """Re-initialise the particles around ``pose`` (used for localization resets)."""
        sxy = self.cfg.init_std_xy_m if std_xy_m is None else std_xy_m
        sth = self.cfg.init_std_theta_rad if std_theta_rad is None else std_theta_rad
        n = self.cfg.n_particles
        p = np.empty((n, 3))
        p[:, :2] = np.asarray(pose[:2], dtype=np.float64) + sxy * self.rng.standard_normal((n, 2))
        p[:, 2] = wrap_angles(float(pose[2]) + sth * self.rng.standard_normal(n))
        self.particles = p
        self.weights = np.full(n, 1.0 / n)
        self.before_refinement = p.copy()
        self.after_refinement = p.copy()
        self.refined_weights = self.weights.copy()

    def estimate(self) -> Estimate:
        p, w = self.particles, self.weights
        mean_xy = (w[:, None] * p[:, :2]).sum(axis=0)
        th = circular_mean(p[:, 2], w)
        d = p[:, :2] - mean_xy
        cov = (w[:, None, None] * np.einsum("ni,nj->nij", d, d)).sum(axis=0)
        r = math.hypot(float(np.sum(w * np.cos(p[:, 2]))), float(np.sum(w * np.sin(p[:, 2]))))
        std_th = math.sqrt(max(0.0, -2.0 * math.log(max(r, 1e-12))))
        return Estimate(np.array([mean_xy[0], mean_xy[1], th]), float(math.sqrt(np.trace(cov))), std_th, cov)

    @staticmethod
    def spread_at(est: Estimate, points: np.ndarray) -> float:
        """The belief's spread at the points: position spread plus heading spread times
        the points' RMS range."""
        if not len(points):
            return est.std_xy_m
        r = math.sqrt(float(np.mean(np.einsum("ij,ij->i", points, points))))
        return est.std_xy_m + r * est.std_theta_rad

    def gate(self, spread_m: float) -> float:
        """Correspondence gate for this frame: ``observation.max_distance_m``, widened to
        ``gate_sigmas`` times the belief's spread at the points (:meth:`spread_at`), as a
        tracker's validation gate widens with its predicted covariance (ours). A well-
        localized filter keeps the tight gate that rejects people and furniture near
        walls; one that has dead-reckoned through a featureless stretch can still match
        the wall it drifted off.
        """
        base = self.obs.max_distance_m
        k = self.cfg.gate_sigmas
        if k <= 0:
            return base
        return max(base, min(self.cfg.max_gate_m, k * spread_m))

    def robust_scale_m(self, spread_m: float) -> float:
        """Scale c of the robust weights (:attr:`CGRConfig.robust_scale`): that many times
        the larger of the measurement noise and the belief's spread at the points (0: off)."""
        k = self.cfg.robust_scale
        return 0.0 if k <= 0 else k * max(self.obs.sigma_m, spread_m)

    def prior_info(self, est: Estimate) -> np.ndarray:
        """Information (1/sigma^2 for x, y, theta) of the refinement's prior: the belief's
        spread, floored at ``prior_min_xy_m`` and ``prior_min_theta_rad``; zeros when both
        floors are 0 (no prior)."""
        cfg = self.cfg
        if cfg.prior_min_xy_m <= 0 and cfg.prior_min_theta_rad <= 0:
            return np.zeros(3)
        sxy = max(est.std_xy_m, cfg.prior_min_xy_m)
        sth = max(est.std_theta_rad, cfg.prior_min_theta_rad)
        ixy = 0.0 if sxy <= 0 else 1.0 / (sxy * sxy)
        return np.array([ixy, ixy, 0.0 if sth <= 0 else 1.0 / (sth * sth)])

    # -- CGR steps ---------------------------------------------------------------------
    def predict(self, increment: np.ndarray) -> None:
        """Step 1: sample the motion model for an odometry increment (dx, dy, dtheta), centred (``mean_preserving_motion``)."""
        dx, dy, dth = (float(v) for v in increment)
        if not all(math.isfinite(v) for v in (dx, dy, dth)):
            return  # a broken odometry message: keep the belief
        cfg = self.cfg
        tr = math.hypot(dx, dy)
        s_t = max(cfg.alpha3 * tr, cfg.min_translation_std_m)
        s_r = max(cfg.alpha1 * abs(dth) + cfg.alpha2_rad_per_m * tr, cfg.min_rotation_std_rad)
        n = cfg.n_particles
        e = self.rng.standard_normal((n, 3))
        if cfg.mean_preserving_motion and n > 1:
            e = (e - e.mean(axis=0)) * math.sqrt(n / (n - 1.0))
        ix, iy, it = dx + s_t * e[:, 0], dy + s_t * e[:, 1], dth + s_r * e[:, 2]
        th = self.particles[:, 2]
        c, s = np.cos(th), np.sin(th)
        self.particles[:, 0] += c * ix - s * iy
        self.particles[:, 1] += s * ix + c * iy
        self.particles[:, 2] = wrap_angles(th + it)

    def update(self, points: np.ndarray, normals: np.ndarray | None) -> UpdateStats:
        """Steps 2-4 for a 2D observation (robot frame); ``normals`` None = laser model."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        use_n = normals is not None
        nrm = np.ascontiguousarray(normals if use_n else np.zeros_like(pts), dtype=np.float64).reshape(-1, 2)
        stats = UpdateStats(points=len(pts))
        self.before_refinement = self.particles.copy()
        self.last = stats
        self.last_lines = None
        if len(pts) < self.obs.min_points:
            return stats
        est = self.estimate()
        lines = np.ascontiguousarray(self.scene_lines(float(est.pose[0]), float(est.pose[1])), dtype=np.float64).reshape(-1, 4)
        self.last_lines = lines
        if len(lines) == 0:
            return stats
        spread = self.spread_at(est, pts)
        frame = _Frame(
            pts, nrm, use_n, math.cos(self.obs.theta_max_rad), self.gate(spread), self.prior_info(est), self.robust_scale_m(spread)
        )
        refined, lnp0, lnpr = self._refine(frame, est.pose, lines, stats)
        lnp = self._accept(refined, lnp0, lnpr, stats, frame.prior_info)
        self._resample(lnp, stats)
        return stats

    def _refine(
        self, fr: _Frame, shared_pose: np.ndarray, lines: np.ndarray, stats: UpdateStats
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Step 2: every particle refined; returns the refined poses and the observation
        log-likelihoods at the first-stage and refined poses.

        Particles near the proposal mean share its correspondences, hence one moment
        matrix; the others get their own scene lines and correspondences."""
        cfg, n = self.cfg, self.cfg.n_particles
        idx_shared = np.empty(len(fr.pts), dtype=np.int64)
        kept = correspond(lines, shared_pose, fr.pts, fr.nrm, fr.use_n, fr.cos_max, fr.gate, idx_shared)
        matched = idx_shared >= 0  # the association check changes idx_shared in place
        frames_shared = line_frames(lines, shared_pose[0], shared_pose[1])
        stats.used_points = int(kept)
        lnp0 = np.empty(n)
        lnpr = np.empty(n)
        refined = np.empty_like(self.particles)
        d_xy = np.hypot(self.particles[:, 0] - shared_pose[0], self.particles[:, 1] - shared_pose[1])
        d_th = np.abs(wrap_angles(self.particles[:, 2] - shared_pose[2]))
        share = (d_xy <= cfg.share_radius_m) & (d_th <= cfg.share_angle_rad)
        stats.shared = int(share.sum())
        m = np.empty((5, 5))
        if share.any():
            sel = np.flatnonzero(share)
            first = np.ascontiguousarray(self.particles[sel])
            refined[sel], lnp0[sel], lnpr[sel] = self._refine_shared(fr, shared_pose, lines, frames_shared, idx_shared, first, m, stats)
        own = np.flatnonzero(~share)
        if (
            cfg.tail_hold_fraction > 0 and len(own) and share.any() and not np.isfinite(lnpr[share]).any()
            and self._accounted(fr, shared_pose, lines, matched, kept) >= cfg.tail_hold_fraction * len(fr.pts)
        ):
            # The samples round the mean account for most of the frame's points (on
            # lines, or in front of the walls as clutter), yet none of them was scored
            # (the association check dropped the points where the refinement led, or
            # fewer than min_points were matched): the frame is ambiguous, not evidence
            # against them. So the few in the tail are not scored either: one refined on
            # its own correspondences would otherwise take every weight from samples that
            # were not scored at all (the GHC2 sliver and furniture frames of
            # docs/localization.md). When the samples round the mean see most points
            # through the walls (their heading off after a sharp turn), the tail is
            # scored and may take the belief.
            stats.unscored_tail = len(own)
            refined[own], lnp0[own], lnpr[own] = self.particles[own], -np.inf, -np.inf
            return refined, lnp0, lnpr
        for i in own:
            refined[i], lnp0[i], lnpr[i] = self._refine_own(fr, self.particles[i], m)
        if cfg.rescore_shared and len(own) and share.any() and _best(lnp0[own], lnpr[own]) > _best(lnp0[share], lnpr[share]):
            # Sharing the mean's lines is a shortcut that holds while the samples round it
            # would pick the same ones; where it decides which samples survive, they are
            # scored as the tail was, each on its own (docs/localization.md).
            stats.rescored = int(share.sum())
            for i in np.flatnonzero(share):
                refined[i], lnp0[i], lnpr[i] = self._refine_own(fr, self.particles[i], m)
        return refined, lnp0, lnpr

    def _accounted(self, fr: _Frame, pose: np.ndarray, lines: np.ndarray, matched: np.ndarray, kept: int) -> int:
        """How many of the frame's points ``pose`` accounts for: those matched to a line
        (``matched``, ``kept`` of them) and, when those are too few for
        ``tail_hold_fraction``, those whose ray from ``pose`` meets no wall or meets its
        first wall more than the gate beyond the point: clutter the map does not hold
        (furniture, people), which the map allows there though it cannot place it. Points
        the walls would hide (the first wall along the ray more than the gate short of the
        point) and points turned away from their line are not accounted for. Rays start
        at the robot's centre, as :func:`autonomy.localization.observation.correspond`'s do."""
        n = len(fr.pts)
        if kept >= self.cfg.tail_hold_fraction * n:
            return kept
        q = points_from_frame(pose, fr.pts) - pose[:2]  # the rays, world frame
        r = np.hypot(q[:, 0], q[:, 1])
        ok = r > 0.0
        dirs = np.zeros_like(q)
        dirs[ok] = q[ok] / r[ok, None]
        hit, t = rays_hit(lines, float(pose[0]), float(pose[1]), dirs)
        clutter = ok & ~matched & ((hit < 0) | (t > r + fr.gate))
        return kept + int(clutter.sum())

    def _refine_shared(
        self,
        fr: _Frame,
        shared_pose: np.ndarray,
        lines: np.ndarray,
        frames: np.ndarray,
        idx: np.ndarray,
        first: np.ndarray,
        m: np.ndarray,
        stats: UpdateStats,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Step 2 for the particles ``first`` that share the proposal mean's
        correspondences ``idx`` (changed in place by the association check).

        With robust weights the refinement runs twice (two rounds of iteratively
        reweighted least squares, ours): first with the points weighed at the proposal
        mean on the belief's scale, then weighed again on the noise's scale at the pose
        that fits them best (:meth:`_reweigh`). A wide belief widens the first scale, so
        points matched to the wrong line still count then (14 points past a wall's end
        matched to a line 0.69 m behind it, with the belief 0.47 m wide); where the good
        points put the pose, the wrong ones stand out."""
        cfg, obs = self.cfg, self.obs
        k, iters = obs.inv_two_f_sigma2, cfg.refinements
        o_p, o0, o1 = np.empty((len(first), 3)), np.empty(len(first)), np.empty(len(first))
        w = np.empty(len(fr.pts))
        robust_weights(frames, idx, shared_pose, fr.pts, fr.robust_m, w)
        used = moments(frames, idx, fr.pts, m, w)
        proj = self._trusted(frames, idx, shared_pose, fr.pts, m, w, stats)
        refine_all_m(
            m, used, first, k, iters, cfg.step_fraction, obs.min_points, o_p, o0, o1, cfg.trust_region_m, fr.prior_info, proj, shared_pose,
        )
        if iters == 0 or used < obs.min_points:
            return o_p, o0, o1
        again = False
        if cfg.consistent_fraction > 0:
            same = self._kept_associations(fr, shared_pose, lines, idx, o_p, m, used)
            if same is not None and same.sum() < cfg.consistent_fraction * used:
                stats.dropped_points = int(used - same.sum())
                idx[~same] = -1
                again = True
        if fr.robust_m > 0:
            self._reweigh(frames, idx, shared_pose, fr.pts, m, used, w)
            again = True
        if again:
            used = moments(frames, idx, fr.pts, m, w)
            proj = self._trusted(frames, idx, shared_pose, fr.pts, m, w, stats)
            refine_all_m(
                m, used, first, k, iters, cfg.step_fraction, obs.min_points, o_p, o0, o1, cfg.trust_region_m, fr.prior_info, proj,
                shared_pose,
            )
            stats.used_points = int(used)
        return o_p, o0, o1

    def _reweigh(
        self, frames: np.ndarray, idx: np.ndarray, pose: np.ndarray, pts: np.ndarray, m: np.ndarray, used: int, w: np.ndarray
    ) -> None:
        """The second round's weights, into ``w``: at the pose that best fits the points
        as the moment matrix ``m`` weighs them, from ``pose`` along every direction, on the
        likelihood alone (within the trust region), and on the scale of what is left
        there: ``robust_scale`` times the larger of sigma and the residuals' robust
        standard deviation (1.4826 times their median absolute value). Along every
        direction, not only the trusted ones: points that alone pin a direction the belief
        is off along (a door jamb ahead of a robot that drifted along a corridor) fit
        there and keep their weight; points that disagree with the others along what
        those pin down (matched to the wrong line) do not. A fit the trust region cut
        short (a heading 20 degrees off after a sharp turn) leaves most residuals large,
        and the scale with them."""
        cfg, obs = self.cfg, self.obs
        fit = np.empty((1, 3))
        refine_all_m(
            m, used, pose[None, :].copy(), obs.inv_two_f_sigma2, cfg.refinements, cfg.step_fraction, obs.min_points, fit, np.empty(1),
            np.empty(1), cfg.trust_region_m,
        )
        at = fit[0]
        sel = idx >= 0
        c, s = math.cos(at[2]), math.sin(at[2])
        q = pts[sel]
        f = frames[idx[sel]]
        d = f[:, 0] * (c * q[:, 0] - s * q[:, 1] + at[0]) + f[:, 1] * (s * q[:, 0] + c * q[:, 1] + at[1]) - f[:, 2]
        spread = ROBUST_SIGMA_PER_MAD * float(np.median(np.abs(d))) if len(d) else 0.0
        robust_weights(frames, idx, at, pts, self.robust_scale_m(spread), w)

    def _trusted(
        self, frames: np.ndarray, idx: np.ndarray, pose: np.ndarray, pts: np.ndarray, m: np.ndarray, w: np.ndarray,
        stats: UpdateStats | None,
    ) -> np.ndarray:
        """The projector on the directions this frame's correspondences, weighed by ``w``,
        pin down (:func:`autonomy.localization.observation.trusted_directions`, ``degeneracy_max_gain``)."""
        proj = np.empty((3, 3))
        k = trusted_directions(frames, idx, pose, pts, moments_lever(m), self.cfg.degeneracy_max_gain, proj, w)
        if stats is not None:
            stats.trusted_directions = int(k)
        return proj

    def _kept_associations(
        self, fr: _Frame, shared_pose: np.ndarray, lines: np.ndarray, idx: np.ndarray, refined: np.ndarray, m: np.ndarray, used: int
    ) -> np.ndarray | None:
        """Association check (ours): which points keep their line at the refined mean.

        Correspondences are found again where the refinement led. A box's face beside a
        pillar, matched to the pillar's extended line, slides onto that line but off its
        segment: those points lose their line there. None (no check) when the
        refinement moved the points less than their noise (sigma): the correspondences
        there are the same."""
        obs = self.obs
        at = np.array([refined[:, 0].mean(), refined[:, 1].mean(), circular_mean(refined[:, 2])])
        lever = moments_lever(m)  # RMS range of the used points
        moved = math.hypot(at[0] - shared_pose[0], at[1] - shared_pose[1]) + lever * abs(float(wrap_angles(at[2] - shared_pose[2])))
        if moved <= obs.sigma_m:
            return None
        idx_at = np.empty(len(fr.pts), dtype=np.int64)
        correspond(lines, at, fr.pts, fr.nrm, fr.use_n, fr.cos_max, obs.max_distance_m, idx_at)
        return (idx >= 0) & (idx_at == idx)

    def _refine_own(self, fr: _Frame, p: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, float, float]:
        """Step 2 for a particle away from the proposal mean: its own scene lines and
        correspondences."""
        cfg, obs = self.cfg, self.obs
        own = np.ascontiguousarray(self.scene_lines(float(p[0]), float(p[1])), dtype=np.float64).reshape(-1, 4)
        idx = np.full(len(fr.pts), -1, dtype=np.int64)
        frames = np.zeros((0, 3))
        if len(own):
            correspond(own, p, fr.pts, fr.nrm, fr.use_n, fr.cos_max, fr.gate, idx)
            frames = line_frames(own, p[0], p[1])
        w = np.empty(len(fr.pts))
        robust_weights(frames, idx, p, fr.pts, fr.robust_m, w)
        used = moments(frames, idx, fr.pts, m, w)
        if fr.robust_m > 0 and cfg.refinements > 0 and used >= obs.min_points:
            # The second round of the shared refinement (:meth:`_refine_shared`).
            self._reweigh(frames, idx, p, fr.pts, m, used, w)
            used = moments(frames, idx, fr.pts, m, w)
        proj = self._trusted(frames, idx, p, fr.pts, m, w, None)
        o_p, o0, o1 = np.empty((1, 3)), np.empty(1), np.empty(1)
        refine_all_m(
            m, used, p[None, :].copy(), obs.inv_two_f_sigma2, cfg.refinements, cfg.step_fraction, obs.min_points, o_p, o0, o1,
            cfg.trust_region_m, fr.prior_info, proj, p,
        )
        return o_p[0], o0[0], o1[0]

    def _accept(
        self, refined: np.ndarray, lnp0: np.ndarray, lnpr: np.ndarray, stats: UpdateStats, prior_info: np.ndarray | None = None
    ) -> np.ndarray:
        """Step 3: the acceptance test between each refined sample and its first-stage
        version, on likelihood times the refinement's prior (centred on the first-stage
        pose, so 1 there); returns the log-likelihood of the sample kept."""
        n = self.cfg.n_particles
        u = self.rng.uniform(size=n)
        with np.errstate(invalid="ignore", over="ignore"):
            gain = lnpr - lnp0  # -inf - -inf is NaN: not accepted
            if prior_info is not None and np.any(prior_info > 0):
                d = refined - self.particles
                d[:, 2] = wrap_angles(d[:, 2])
                gain = gain - 0.5 * (d * d) @ prior_info
            accept = np.isfinite(lnpr) & ((gain >= 0) | (np.log(np.maximum(u, 1e-300)) < gain))
        self.particles[accept] = refined[accept]
        self.particles[:, 2] = wrap_angles(self.particles[:, 2])
        stats.accepted_refinements = int(accept.sum()) if self.cfg.refinements > 0 else 0
        return np.where(accept, lnpr, lnp0)

    def _resample(self, lnp: np.ndarray, stats: UpdateStats) -> None:
        """Step 4: importance weights and low-variance resampling (uniform weights, and
        no resampling, when no sample has a finite likelihood)."""
        n = self.cfg.n_particles
        finite = np.isfinite(lnp)
        if not finite.any():
            self.weights = np.full(n, 1.0 / n)
            return
        w = np.where(finite, np.exp(lnp - lnp[finite].max()), 0.0)
        total = w.sum()
        if not (total > 0 and math.isfinite(total)):
            self.weights = np.full(n, 1.0 / n)
            return
        self.weights = w / total
        self.after_refinement = self.particles.copy()
        self.refined_weights = self.weights.copy()
        stats.observation = True
        idx = low_variance_resample(self.weights, self.rng)
        self.particles = self.particles[idx]
        self.weights = np.full(n, 1.0 / n)

    def step(self, increment: np.ndarray, points: np.ndarray, normals: np.ndarray | None) -> Estimate:
        """One frame: predict with the odometry increment, update with the observation."""
        self.predict(increment)
        self.update(points, normals)
        return self.estimate()
