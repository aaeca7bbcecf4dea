"""Localization health: the per-point verdicts against a brute-force reference, and the
monitor's lost / blind decisions on verdict streams with a closed-form answer."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.localization.health import HealthConfig, HealthMonitor, explain_points
from autonomy.maps.raycast import SceneQuery, rays_hit
from sim.simulator.blueprints import load_blueprint

CFG = HealthConfig()
FPS = 30.0
EPS = 1e-6
"""Points within this of a decision boundary (a segment's end, a tie between two walls,
the explain or through distance) are left out of the comparison with the reference."""


# --------------------------------------------------------------------------- explain_points


def reference_verdicts(lines: np.ndarray, pose: np.ndarray, pts: np.ndarray, explain_m: float, through_m: float):
    """Pure-python explain_points: per point the verdict and whether it lies within EPS
    of a decision boundary (where float rounding may decide either way)."""
    x, y, th = (float(v) for v in pose)
    out, unsure = [], []
    for px, py in pts:
        qx = math.cos(th) * px - math.sin(th) * py
        qy = math.sin(th) * px + math.cos(th) * py
        r = math.hypot(qx, qy)
        if r == 0.0:
            out.append(0)
            unsure.append(False)
            continue
        d = np.array([qx / r, qy / r])
        hits = []  # (t, line) of every line the ray crosses
        near_end = False
        for a0x, a0y, a1x, a1y in lines:
            e = np.array([a1x - a0x, a1y - a0y])
            m = np.column_stack([d, -e])  # o + t d = a0 + u e
            if abs(np.linalg.det(m)) < 1e-9 * max(1.0, float(e @ e)):
                continue
            t, u = np.linalg.solve(m, np.array([a0x - x, a0y - y]))
            if t > EPS and -EPS <= u <= 1 + EPS:
                near_end |= min(abs(u), abs(u - 1)) < EPS
                hits.append((t, (a0x, a0y, a1x, a1y)))
            elif abs(t) <= EPS and -EPS <= u <= 1 + EPS:
                near_end = True  # the line passes through the robot
        if not hits:
            out.append(0)
            unsure.append(near_end)
            continue
        hits.sort(key=lambda h: h[0])
        t, (a0x, a0y, a1x, a1y) = hits[0]
        tie = len(hits) > 1 and hits[1][0] - t < EPS
        wx, wy = x + qx, y + qy
        dist = abs((wx - a0x) * (a1y - a0y) - (wy - a0y) * (a1x - a0x)) / math.hypot(a1x - a0x, a1y - a0y)
        if r > t + through_m:
            v = -1
        elif dist <= explain_m:
            v = 1
        else:
            v = 0
        out.append(v)
        unsure.append(near_end or tie or abs(r - t - through_m) < EPS or abs(dist - explain_m) < EPS)
    return np.array(out, dtype=np.int8), np.array(unsure, dtype=bool)


def first_hits(lines: np.ndarray, pose: np.ndarray, ang_robot: np.ndarray) -> np.ndarray:
    """Distance to the first line along each robot-frame bearing (inf: none)."""
    a = pose[2] + ang_robot
    idx, t = rays_hit(lines, pose[0], pose[1], np.column_stack([np.cos(a), np.sin(a)]))
    return np.where(idx >= 0, t, np.inf)


@settings(max_examples=150, deadline=None)
@given(
    segs=st.lists(
        st.tuples(*[st.floats(-5.0, 5.0, allow_nan=False, allow_subnormal=False)] * 4), min_size=1, max_size=10
    ),
    pose=st.tuples(
        st.floats(-4.0, 4.0, allow_subnormal=False), st.floats(-4.0, 4.0, allow_subnormal=False), st.floats(-math.pi, math.pi)
    ),
    seed=st.integers(0, 2**32 - 1),
)
def test_explain_points_matches_a_brute_force_reference(segs, pose, seed) -> None:
    lines = np.array(segs, dtype=np.float64)
    assume(np.all(np.hypot(lines[:, 2] - lines[:, 0], lines[:, 3] - lines[:, 1]) > 1e-3))
    p = np.array(pose, dtype=np.float64)
    rng = np.random.default_rng(seed)
    n = 60
    ang = rng.uniform(-math.pi, math.pi, n)
    hit = first_hits(lines, p, ang)
    # Ranges round the first wall of each ray (on it, just off it, beyond it, short of
    # it) so all three verdicts occur; rays that hit nothing get a random range.
    off = rng.choice([0.0, 0.1, -0.1, 0.3, 0.6, 1.5, -0.5, -2.0], n) + rng.normal(0.0, 0.02, n)
    r = np.where(np.isfinite(hit), np.maximum(hit + off, 0.0), rng.uniform(0.0, 8.0, n))
    r[: n // 10] = rng.uniform(0.0, 8.0, n // 10)
    pts = np.column_stack([r * np.cos(ang), r * np.sin(ang)])
    pts[0] = 0.0  # a point at the robot: no ray, no verdict
    got = explain_points(lines, p, pts, CFG.explain_m, CFG.through_m)
    want, unsure = reference_verdicts(lines, p, pts, CFG.explain_m, CFG.through_m)
    assert got.dtype == np.int8 and got.shape == (n,)
    np.testing.assert_array_equal(got[~unsure], want[~unsure])


@pytest.fixture(scope="module")
def corridor_scene() -> SceneQuery:
    return SceneQuery(load_blueprint("corridor_loop").vectormap)


#: Free poses of corridor_loop: a corridor, an office, the atrium.
POSES = [np.array([30.0, 6.3, 0.4]), np.array([10.5, 2.6, -2.0]), np.array([30.0, 12.0, 1.2])]


@pytest.mark.parametrize("pose", POSES, ids=["corridor", "office", "atrium"])
def test_points_on_walls_are_explained_beyond_them_contradict_and_short_of_them_are_neutral(corridor_scene, pose) -> None:
    lines = np.ascontiguousarray(corridor_scene.scene_lines(pose[0], pose[1])[0])
    ang = np.linspace(-math.pi, math.pi, 720, endpoint=False)  # robot frame
    world = np.column_stack([np.cos(ang + pose[2]), np.sin(ang + pose[2])])
    idx, t = rays_hit(lines, pose[0], pose[1], world)
    ok = (idx >= 0) & (t > 0.5)
    ang, world, t, seg = ang[ok], world[ok], t[ok], lines[idx[ok]]
    assert len(t) > 150
    robot = np.column_stack([np.cos(ang), np.sin(ang)])

    def verdicts(r: np.ndarray) -> np.ndarray:
        return explain_points(lines, pose, r[:, None] * robot, CFG.explain_m, CFG.through_m)

    # Exactly on the first wall of each ray.
    assert np.all(verdicts(t) == 1)
    # Beyond it by more than through_m (whatever lies there: another wall, a room).
    assert np.all(verdicts(t + CFG.through_m + 0.05) == -1)
    # Beyond it by less than through_m, or short of it (clutter): explained only while
    # within explain_m of the wall's line (a ray at a grazing angle), else neutral.
    a, e = seg[:, :2], seg[:, 2:] - seg[:, :2]
    for r in (t + 0.5 * CFG.through_m, t - 0.3, 0.5 * t):
        w = pose[:2] + r[:, None] * world
        dist = np.abs((w[:, 0] - a[:, 0]) * e[:, 1] - (w[:, 1] - a[:, 1]) * e[:, 0]) / np.hypot(e[:, 0], e[:, 1])
        sure = np.abs(dist - CFG.explain_m) > EPS
        want = np.where(dist <= CFG.explain_m, 1, 0)
        np.testing.assert_array_equal(verdicts(r)[sure], want[sure])
    assert np.count_nonzero(verdicts(0.5 * t) == 0) > 0.8 * len(t)


def test_a_point_on_a_wall_hidden_behind_the_first_contradicts() -> None:
    # Two parallel walls at x = 2 and x = 3; the robot at the origin facing +x.
    lines = np.array([[2.0, -5.0, 2.0, 5.0], [3.0, -5.0, 3.0, 5.0]])
    pts = np.array([[2.0, 0.0], [3.0, 0.0], [2.3, 0.0], [1.0, 0.0], [2.0, 1.0], [-3.0, 0.5]])
    got = explain_points(lines, np.zeros(3), pts, CFG.explain_m, CFG.through_m)
    # on the first wall, on the hidden one, 0.3 beyond (< through_m, off the line),
    # clutter, on the first wall off-axis, behind the robot (no wall on its ray).
    np.testing.assert_array_equal(got, [1, -1, 0, 0, 1, 0])
    # The same points with the robot turned: robot-frame points turn with it.
    turned = explain_points(lines, np.array([0.0, 0.0, math.pi]), -pts, CFG.explain_m, CFG.through_m)
    np.testing.assert_array_equal(turned, got)


# --------------------------------------------------------------------------- the monitor


def frame(rng: np.random.Generator, explained: float, through: float = 0.0, n: int = 200) -> np.ndarray:
    """A frame's verdicts with exactly these fractions (of ``n`` points), shuffled."""
    k1, k2 = int(round(explained * n)), int(round(through * n))
    v = np.zeros(n, np.int8)
    v[:k1], v[k1 : k1 + k2] = 1, -1
    return rng.permutation(v)


def run(mon: HealthMonitor, t0: float, seconds: float, make, spread: float = 0.1):
    """Feed ``make(t)`` at 30 Hz for ``seconds`` from ``t0``; returns (times, samples)."""
    ts = t0 + np.arange(1, int(round(seconds * FPS)) + 1) / FPS
    return ts, [mon.update(float(t), make(t), spread) for t in ts]


def first_state(ts, samples, state: str) -> float:
    hit = [t for t, s in zip(ts, samples, strict=True) if s.state == state]
    return hit[0] if hit else math.inf


def test_constant_good_frames_stay_ok() -> None:
    rng = np.random.default_rng(0)
    mon = HealthMonitor()
    _, samples = run(mon, 0.0, 60.0, lambda t: frame(rng, rng.uniform(0.6, 0.9), rng.uniform(0.0, 0.05)))
    assert {s.state for s in samples} == {"ok"} and all(s.reason == "" for s in samples)
    assert 0.6 < samples[-1].explained_slow < 0.9


@settings(max_examples=40, deadline=None)
@given(level=st.floats(0.0, 1.0), fps=st.floats(3.0, 60.0), n=st.integers(CFG.min_points, 400))
def test_a_steady_explained_fraction_at_any_level_never_says_lost(level, fps, n) -> None:
    """A low level that stays low (an atrium with few walls in view) is normal there."""
    mon = HealthMonitor()
    v = frame(np.random.default_rng(1), level, 0.0, n)
    for t in np.arange(1, int(40 * fps)) / fps:
        assert mon.update(float(t), v, 0.2).state == "ok"


def test_a_low_but_steady_atrium_level_stays_ok_while_a_kidnap_to_a_low_level_is_lost() -> None:
    rng = np.random.default_rng(2)
    atrium = HealthMonitor()
    _, samples = run(atrium, 0.0, 60.0, lambda t: frame(rng, rng.uniform(0.05, 0.2), rng.uniform(0.0, 0.05)))
    assert {s.state for s in samples} == {"ok"}
    kidnapped = HealthMonitor()
    run(kidnapped, 0.0, 20.0, lambda t: frame(rng, 0.8))
    low = CFG.lost_ratio * 0.8  # a level far below the place's usual one
    ts, samples = run(kidnapped, 20.0, 8.0, lambda t: frame(rng, rng.uniform(0.25, 0.75) * low, rng.uniform(0.0, 0.05)))
    assert first_state(ts, samples, "lost") < 28.0


def lost_time_after_a_step(e0: float, e1: float, cfg: HealthConfig = CFG) -> float:
    """Closed form of the ratio test after a step of the explained fraction from a steady
    ``e0`` to ``e1`` at time 0: both averages relax exponentially to ``e1`` (a first-order
    filter sampled at the frames is exact for a step), the test first holds at the first
    frame where fast < lost_ratio * slow, and lost follows ``ratio_hold_s`` later (frames)."""
    ts = np.arange(1, int(20 * FPS)) / FPS
    fast = e1 + (e0 - e1) * np.exp(-ts / cfg.fast_s)
    slow = e1 + (e0 - e1) * np.exp(-ts / cfg.slow_s)
    bad = ts[np.argmax(fast < cfg.lost_ratio * slow)]
    return float(ts[np.argmax(ts - bad >= cfg.ratio_hold_s - 1e-9)])


@pytest.mark.parametrize("share", [0.0, 0.5])
def test_a_sudden_drop_of_the_explained_fraction_is_lost_after_the_closed_form_delay(share) -> None:
    """A kidnap: from 0.8 explained to nothing, or to half of lost_ratio times that."""
    rng = np.random.default_rng(3)
    mon = HealthMonitor()
    after = round(share * CFG.lost_ratio * 0.8 * 200) / 200  # a whole number of the 200 points
    run(mon, 0.0, 20.0, lambda t: frame(rng, 0.8))
    ts, samples = run(mon, 20.0, 8.0, lambda t: frame(rng, after))
    lost = first_state(ts, samples, "lost") - 20.0
    want = lost_time_after_a_step(0.8, after)
    assert abs(lost - want) < 1.5 / FPS, (lost, want)
    assert want < CFG.ratio_hold_s + 3.0 * CFG.fast_s  # the short-term average falls within a few time constants
    s = samples[int(round(lost * FPS)) - 1]
    assert s.state == "lost" and s.reason == "explains little"
    # Never before: ok until the test has held for hold_s.
    assert all(x.state == "ok" for t, x in zip(ts, samples, strict=True) if t - 20.0 < want - 1e-9)


def test_the_map_tests_hold_only_on_frames_with_evidence() -> None:
    """Two seconds of frames that explain nothing after a well explained corridor, then
    frames too thin to be evidence (open space past the camera's range): the short-term
    average stays low but nothing new is seen, so no alarm however long that lasts. Bad
    frames again: lost once the frames with evidence add up to ``ratio_hold_s``."""
    rng = np.random.default_rng(8)
    mon = HealthMonitor()
    run(mon, 0.0, 20.0, lambda t: frame(rng, 0.8))
    ts, samples = run(mon, 20.0, 2.0, lambda t: frame(rng, 0.0))
    assert {s.state for s in samples} == {"ok"}
    held = ts[-1] - ts[next(i for i, s in enumerate(samples) if s.explained_fast < CFG.lost_ratio * s.explained_slow)]
    assert 0.0 < held < CFG.ratio_hold_s
    _, thin = run(mon, 22.0, 30.0, lambda t: frame(rng, 0.0, 0.0, CFG.min_points - 1))
    assert {s.state for s in thin} == {"ok"} and thin[-1].explained_fast < CFG.lost_ratio * thin[-1].explained_slow
    ts, samples = run(mon, 52.0, 8.0, lambda t: frame(rng, 0.0))
    lost = first_state(ts, samples, "lost") - 52.0
    assert samples[int(round(lost * FPS)) - 1].reason == "explains little"
    # The first bad frame after the gap counts the time since the last frame, 1 / FPS.
    assert abs(lost - (CFG.ratio_hold_s - held)) < 1.5 / FPS, (lost, held)


def test_frames_with_evidence_every_other_frame_take_twice_as_long_to_say_lost() -> None:
    rng = np.random.default_rng(9)
    every, alternate = HealthMonitor(), HealthMonitor()
    run(every, 0.0, 20.0, lambda t: frame(rng, 0.8))
    run(alternate, 0.0, 20.0, lambda t: frame(rng, 0.8))
    ts, a = run(every, 20.0, 12.0, lambda t: frame(rng, 0.0))
    _, b = run(alternate, 20.0, 12.0, lambda t: frame(rng, 0.0, 0.0, 200 if round(t * FPS) % 2 == 0 else CFG.min_points - 1))
    bad_a = first_state(ts, a, "lost") - 20.0
    bad_b = first_state(ts, b, "lost") - 20.0
    # Both averages fall by the same law on the frames with evidence; the hold then
    # needs twice the frames.
    assert bad_a < bad_b < math.inf
    assert b[int(round(bad_b * FPS)) - 1].reason == "explains little"
    assert bad_b - bad_a > 0.8 * CFG.ratio_hold_s


def test_the_ratio_test_waits_for_history() -> None:
    """Right after a reset the long-term level is not known yet: a drop then is no alarm."""
    rng = np.random.default_rng(4)
    mon = HealthMonitor()
    history = CFG.min_history_s - 2.0
    run(mon, 0.0, history, lambda t: frame(rng, 0.8))
    _, samples = run(mon, history, 1.9, lambda t: frame(rng, 0.0))
    assert {s.state for s in samples} == {"ok"}


def test_seeing_through_walls_is_lost_after_the_closed_form_delay_without_history() -> None:
    rng = np.random.default_rng(5)
    mon = HealthMonitor()
    through = 0.5
    run(mon, 0.0, 1.0, lambda t: frame(rng, 0.4, 0.0))
    ts, samples = run(mon, 1.0, 3.0, lambda t: frame(rng, 0.3, through))
    lost = first_state(ts, samples, "lost")
    # The short-term contradiction average after the step, at the frames, and the
    # first frame it is above lost_through; lost hold_s after that.
    th_fast = through * (1.0 - np.exp(-(ts - 1.0) / CFG.fast_s))
    bad = ts[np.argmax(th_fast > CFG.lost_through)]
    assert bad - 1.0 == pytest.approx(CFG.fast_s * math.log(through / (through - CFG.lost_through)), abs=1.0 / FPS)
    assert CFG.hold_s - 1e-9 <= lost - bad <= CFG.hold_s + 1.01 / FPS
    assert samples[int(round((lost - 1.0) * FPS)) - 1].reason == "sees through walls"


def test_a_wide_spread_is_lost_after_hold_s_and_a_short_one_is_not() -> None:
    rng = np.random.default_rng(6)
    wide = CFG.lost_spread_m * 1.5
    mon = HealthMonitor()
    run(mon, 0.0, 2.0, lambda t: frame(rng, 0.8))
    ts = 2.0 + np.arange(1, 61) / FPS
    samples = [mon.update(float(t), frame(rng, 0.8), wide) for t in ts]
    lost = first_state(ts, samples, "lost")
    assert CFG.hold_s - 1e-9 <= lost - ts[0] <= CFG.hold_s + 1.01 / FPS and samples[-1].reason == "spread"
    # A spread of exactly the threshold, and a wide one shorter than hold_s: ok.
    brief = HealthMonitor()
    for i in range(1, 301):
        t = i / FPS
        spread = CFG.lost_spread_m if i < 100 else (wide if 150 <= i < 150 + int(0.8 * CFG.hold_s * FPS) else 0.1)
        assert brief.update(t, frame(rng, 0.8), spread).state == "ok", t


def test_no_frames_for_longer_than_blind_s_is_blind_and_thin_frames_are_not() -> None:
    rng = np.random.default_rng(7)
    mon = HealthMonitor()
    run(mon, 0.0, 2.0, lambda t: frame(rng, 0.8))
    # Frames with fewer than min_points points: no evidence, but the camera works.
    _, thin = run(mon, 2.0, 3.0, lambda t: frame(rng, 0.5, 0.0, CFG.min_points - 1))
    assert {s.state for s in thin} == {"ok"} and all(math.isnan(s.explained) for s in thin)
    ts, samples = run(mon, 5.0, 2.0, lambda t: None)
    blind = first_state(ts, samples, "blind") - 5.0
    assert CFG.blind_s < blind <= CFG.blind_s + 1.01 / FPS
    assert samples[-1].state == "blind" and samples[-1].reason == "no frames"
    # Blind is not lost: the short-term averages hold, nothing accumulates.
    assert {s.state for s in samples} <= {"ok", "blind"}
    _, back = run(mon, 7.0, 0.5, lambda t: frame(rng, 0.8))
    assert {s.state for s in back} == {"ok"}


def test_reset_clears_the_state_and_the_averages() -> None:
    rng = np.random.default_rng(8)
    mon = HealthMonitor()
    run(mon, 0.0, 20.0, lambda t: frame(rng, 0.8))
    _, samples = run(mon, 20.0, 7.0, lambda t: frame(rng, 0.0))
    assert samples[-1].state == "lost"
    mon.reset(27.0)
    assert mon.state == "ok" and mon.reason == "" and math.isnan(mon.e_slow) and mon.history_s == 0.0
    assert math.isnan(mon.e_fast) and math.isnan(mon.th_fast) and mon.last.state == "ok"
    # After the reset the low level is the new normal: no history, no ratio test.
    _, samples = run(mon, 27.0, 4.0, lambda t: frame(rng, 0.0))
    assert {s.state for s in samples} == {"ok"}


def test_reset_keeping_the_long_term_level_keeps_it() -> None:
    rng = np.random.default_rng(9)
    keep = HealthMonitor()
    run(keep, 0.0, 20.0, lambda t: frame(rng, 0.8))
    keep.reset(20.0, keep_long_term=True)
    assert keep.state == "ok" and keep.history_s >= CFG.min_history_s and abs(keep.e_slow - 0.8) < 1e-9
    # The same drop as after a kidnap: the kept level makes it lost again.
    _, samples = run(keep, 20.0, 7.0, lambda t: frame(rng, 0.0))
    assert samples[-1].state == "lost"


def test_a_second_frame_at_the_same_time_moves_no_average() -> None:
    rng = np.random.default_rng(10)
    mon = HealthMonitor()
    run(mon, 0.0, 20.0, lambda t: frame(rng, 0.8))
    before = (mon.e_fast, mon.e_slow)
    mon.update(20.0, frame(rng, 0.0), 0.1)  # no time has passed: no weight
    assert (mon.e_fast, mon.e_slow) == pytest.approx(before)


@pytest.mark.parametrize(
    ("field", "value"), [("explain_m", 0.0), ("through_m", -1.0), ("blind_s", math.nan), ("hold_s", -0.1), ("lost_ratio", "0.3"),
     ("jump_m", 0.0), ("jump_s", -1.0), ("jump_ratio", -0.1), ("view_agree", -0.5), ("lost_missing", -0.1), ("view_frames", 0), ("view_frames", 1.5)]
)
def test_bad_config_is_a_one_line_error_naming_the_field(field, value) -> None:
    with pytest.raises(InputError, match=rf"health\.{field}: expected"):
        HealthConfig(**{field: value})


# --------------------------------------------------------------------------- the jump test


def feed(mon: HealthMonitor, t0: float, seconds: float, explained, correction):
    """Feed frames at 30 Hz with ``explained(t)`` verdicts and ``correction(t)`` (world
    x, y of the localizer's correction); returns (times, corrections, samples)."""
    rng = np.random.default_rng(11)
    ts = t0 + np.arange(1, int(round(seconds * FPS)) + 1) / FPS
    cs, samples = [], []
    for t in ts:
        c = correction(float(t))
        cs.append(c)
        samples.append(mon.update(float(t), frame(rng, explained(float(t))), 0.05, c))
    return ts, cs, samples


def reference_jump(ts, cs, k: int, window_s: float) -> float:
    """Brute force: the norm of the sum of the corrections within ``window_s`` up to frame k."""
    sx = sy = 0.0
    for t, c in zip(ts[: k + 1], cs[: k + 1], strict=True):
        if t > ts[k] - window_s:
            sx, sy = sx + c[0], sy + c[1]
    return math.hypot(sx, sy)


def test_the_net_correction_matches_a_brute_force_window_sum() -> None:
    rng = np.random.default_rng(12)
    mon = HealthMonitor()
    steps = rng.normal(0.0, 0.03, (int(20 * FPS), 2)) + np.array([0.004, -0.002])
    ts, cs, samples = feed(mon, 0.0, 20.0, lambda t: 0.8, lambda t: tuple(steps[int(round(t * FPS)) - 1]))
    for k in range(0, len(ts), 7):
        assert samples[k].jump_m == pytest.approx(reference_jump(ts, cs, k, CFG.jump_s), abs=1e-9)


def test_a_jump_after_the_view_stopped_fitting_is_lost_at_once() -> None:
    """A robot carried along a corridor: the explained fraction falls to a third of its
    level (above the ratio test's), then the localizer pulls the belief 0.7 m in 0.3 s."""
    mon = HealthMonitor()
    jitter = np.random.default_rng(13)
    feed(mon, 0.0, 20.0, lambda t: 0.9, lambda t: tuple(jitter.normal(0.0, 0.02, 2)))
    ts, cs, samples = feed(mon, 20.0, 2.0, lambda t: 0.3, lambda t: tuple(jitter.normal(0.0, 0.02, 2)))
    assert {s.state for s in samples} == {"ok"}
    assert samples[-1].explained_fast < CFG.jump_ratio * samples[-1].explained_slow
    per_frame = 0.7 / (0.3 * FPS)
    ts2, cs2, samples2 = feed(mon, 22.0, 1.0, lambda t: 0.6, lambda t: (per_frame, 0.0) if t <= 22.3 + 1e-9 else (0.0, 0.0))
    lost = [k for k, s in enumerate(samples2) if s.state == "lost"]
    assert lost and samples2[lost[0]].reason == "belief jumped"
    ts_all, cs_all = list(ts) + list(ts2), cs + cs2
    first_over = next(k for k in range(len(ts2)) if reference_jump(ts_all, cs_all, len(ts) + k, CFG.jump_s) > CFG.jump_m)
    assert lost[0] == first_over


def test_the_same_jump_while_the_view_still_fits_is_no_alarm() -> None:
    """Wheels slipping under a tracked belief: the localizer corrects the odometry
    quickly but the map keeps explaining what the camera sees."""
    mon = HealthMonitor()
    feed(mon, 0.0, 20.0, lambda t: 0.9, lambda t: (0.0, 0.0))
    per_frame = 0.7 / (0.3 * FPS)
    _, _, samples = feed(mon, 20.0, 3.0, lambda t: 0.8, lambda t: (per_frame, 0.0) if t <= 20.3 else (0.0, 0.0))
    assert {s.state for s in samples} == {"ok"}
    assert max(s.jump_m for s in samples) > CFG.jump_m


def test_a_jump_right_after_a_relocalization_is_lost_at_once() -> None:
    """An accepted pose, right, facing furniture the map lacks: nothing in view is
    explained, and CGR moves the belief 0.75 m and then 0.25 m in two frames to where
    the points fit walls. The reset left no long-term level to compare with; the jump
    alone says lost. CGR settling by a restart spread or two raises nothing."""
    mon = HealthMonitor()
    feed(mon, 0.0, 20.0, lambda t: 0.8, lambda t: (0.0, 0.0))
    mon.reset(20.0)
    _, _, samples = feed(mon, 20.0, 0.7, lambda t: 0.0, lambda t: (0.01, 0.0))
    assert {s.state for s in samples} == {"ok"}
    moves = iter([(0.75, 0.0), (0.25, 0.0)])
    _, _, samples = feed(mon, 20.7, 0.3, lambda t: 0.75, lambda t: next(moves, (0.0, 0.0)))
    assert samples[0].state == "lost" and samples[0].reason == "belief jumped"
    # CGR converging after the restart: 0.3 m in a second.
    mon = HealthMonitor()
    mon.reset(0.0)
    _, _, samples = feed(mon, 0.0, 1.0, lambda t: 0.3, lambda t: (0.3 / FPS, 0.0))
    assert {s.state for s in samples} == {"ok"}
    # With the test off (jump_ratio 0), not even that jump.
    mon = HealthMonitor(HealthConfig(jump_ratio=0.0))
    mon.reset(0.0)
    moves = iter([(0.75, 0.0), (0.25, 0.0)])
    _, _, samples = feed(mon, 0.0, 0.3, lambda t: 0.0, lambda t: next(moves, (0.0, 0.0)))
    assert all(s.reason != "belief jumped" for s in samples)


@settings(max_examples=30, deadline=None)
@given(rate=st.floats(0.0, 0.95), sigma=st.floats(0.0, 0.05), angle=st.floats(0.0, 2 * math.pi))
def test_jitter_and_slow_corrections_never_jump(rate, sigma, angle) -> None:
    """Corrections below ``jump_m`` per ``jump_s`` (net), with zero-mean jitter on top that
    cancels over the window, raise no jump alarm even when the view fits poorly."""
    mon = HealthMonitor()
    rng = np.random.default_rng(14)
    per_frame = rate * CFG.jump_m / CFG.jump_s / FPS
    drift = (per_frame * math.cos(angle), per_frame * math.sin(angle))
    # Antithetic jitter (each draw followed by its negative): the window's net jitter is
    # at most one draw, so the test is exact.
    draws: list[np.ndarray] = []

    def correction(t: float) -> tuple[float, float]:
        if draws:
            d = -draws.pop()
        else:
            d = np.clip(rng.normal(0.0, sigma, 2), -0.05, 0.05)
            draws.append(d)
        return (drift[0] + d[0] * (1.0 - rate), drift[1] + d[1] * (1.0 - rate))

    feed(mon, 0.0, 10.0, lambda t: 0.9, correction)
    _, _, samples = feed(mon, 10.0, 3.0, lambda t: 0.3, correction)
    assert all(s.reason != "belief jumped" for s in samples)


# --------------------------------------------------------------------------- the view test


def feed_views(mon: HealthMonitor, t0: float, agree: list[float], rng: np.random.Generator):
    """Frames the map explains at 0.8 with the view agreements ``agree`` at 30 Hz;
    returns the samples."""
    ts = t0 + np.arange(1, len(agree) + 1) / FPS
    return [mon.update(float(t), frame(rng, 0.8), 0.1, None, a) for t, a in zip(ts, agree, strict=True)]


def settled(seed: int, cfg: HealthConfig = CFG) -> tuple[HealthMonitor, np.random.Generator]:
    """A monitor after 10 s of frames the map explains at 0.8."""
    rng = np.random.default_rng(seed)
    mon = HealthMonitor(cfg)
    run(mon, 0.0, 10.0, lambda t: frame(rng, 0.8))
    return mon, rng


@pytest.mark.parametrize("frames", [CFG.view_frames, 3])
def test_a_view_disagreeing_with_the_odometry_on_view_frames_frames_is_lost_at_once(frames: int) -> None:
    """Even while the map still explains the view (a kidnapping to a place the belief's
    map fits as well)."""
    mon, rng = settled(12, HealthConfig(view_frames=frames))
    low, high = CFG.view_agree / 2, min(1.0, CFG.view_agree * 3)
    # Frames without evidence (NaN) neither count nor break the run; one agreeing frame does.
    pattern = [high, math.nan] + ([low] * (frames - 1) + [high] if frames > 1 else []) + [low] * (frames - 1) + [math.nan, low]
    samples = feed_views(mon, 10.0, pattern, rng)
    states = [s.state for s in samples]
    assert states[:-1] == ["ok"] * (len(pattern) - 1), states
    assert samples[-1].state == "lost" and samples[-1].reason == "view jumped"
    assert samples[-1].view_agree == low and math.isnan(samples[-2].view_agree)
    assert samples[-1].explained_fast > 0.7


def test_the_view_test_off_or_agreeing_views_never_say_lost() -> None:
    mon, rng = settled(13, HealthConfig(view_agree=0.0))
    assert all(s.state == "ok" for s in feed_views(mon, 10.0, [0.0] * 30, rng))
    mon, rng = settled(15)
    assert all(s.state == "ok" for s in feed_views(mon, 10.0, [CFG.view_agree] * 30 + [math.nan] * 5, rng))


# --------------------------------------------------------------------------- the missing-wall test


def feed_missing(mon: HealthMonitor, t0: float, missing: list[float], rng: np.random.Generator, explained: float = 0.8):
    """Frames the map explains at ``explained`` with the missing-wall fractions ``missing``
    at 30 Hz; returns (times, samples)."""
    ts = t0 + np.arange(1, len(missing) + 1) / FPS
    return ts, [mon.update(float(t), frame(rng, explained), 0.1, None, math.nan, m) for t, m in zip(ts, missing, strict=True)]


@pytest.mark.parametrize("after", [1.0, 0.6])
def test_walls_missing_is_lost_after_the_closed_form_delay(after: float) -> None:
    """A landing in an open hall: from a view where every expected wall was there, to one
    where the camera sees past ``after`` of them. The short-term average relaxes to ``after``
    (a first-order filter sampled at the frames is exact for a step), passes
    ``lost_missing``, and lost follows ``hold_s`` later."""
    mon, rng = settled(21)
    feed_missing(mon, 10.0, [0.0] * 60, rng)
    ts, samples = feed_missing(mon, 12.0, [after] * int(8 * FPS), rng)
    dt = ts - 12.0
    fast = after * (1.0 - np.exp(-dt / CFG.fast_s))
    bad = dt[np.argmax(fast > CFG.lost_missing)]
    want = float(dt[np.argmax(dt - bad >= CFG.hold_s - 1e-9)])
    lost = first_state(ts, samples, "lost") - 12.0
    assert abs(lost - want) < 1.5 / FPS, (lost, want)
    s = samples[int(round(lost * FPS)) - 1]
    assert s.reason == "walls missing" and s.missing == after and s.missing_fast > CFG.lost_missing
    assert s.explained_fast > 0.7  # the map tests alone saw nothing wrong


def test_walls_missing_holds_only_on_frames_with_that_evidence() -> None:
    """Every other frame without pixels expecting a wall (NaN): twice as long to say lost."""
    mon, rng = settled(22)
    ts, samples = feed_missing(mon, 10.0, [1.0] * int(6 * FPS), rng)
    every = first_state(ts, samples, "lost") - 10.0
    mon, rng = settled(22)
    ts, samples = feed_missing(mon, 10.0, [1.0, math.nan] * int(6 * FPS), rng)
    other = first_state(ts, samples, "lost") - 10.0
    assert abs(every - CFG.hold_s) < 1.5 / FPS and abs(other - 2 * CFG.hold_s) < 2.5 / FPS, (every, other)


def test_walls_missing_off_or_below_the_threshold_never_says_lost() -> None:
    mon, rng = settled(23, HealthConfig(lost_missing=0.0))
    assert all(s.state == "ok" for s in feed_missing(mon, 10.0, [1.0] * 300, rng)[1])
    mon, rng = settled(24)
    _, samples = feed_missing(mon, 10.0, [CFG.lost_missing * 0.9] * 600, rng)
    assert all(s.state == "ok" for s in samples) and abs(samples[-1].missing_fast - CFG.lost_missing * 0.9) < 1e-3


def test_a_view_jump_while_walls_are_missing_is_lost_at_once() -> None:
    """The held missing-wall test must not keep a test that says lost at once waiting."""
    mon, rng = settled(25)
    feed_missing(mon, 10.0, [1.0] * 10, rng)  # the missing-wall test holds, not yet for hold_s
    assert mon.state == "ok" and mon.bad_evidence_s < CFG.hold_s
    s = mon.update(10.5, frame(rng, 0.8), 0.1, None, 0.0, 1.0)
    assert s.state == "lost" and s.reason == "view jumped"
