"""Kinect v1 depth-noise model applied to a clean planar depth image.

Terms (each switchable in :class:`KinectNoiseConfig`), applied in this order:

1. Incidence angle ``theta`` per pixel from normals of the *clean* image
   (:func:`incidence_angle`).
2. Projector shadows: pixels the IR projector cannot see are 0 (per-row epipolar scan).
3. Lateral noise (Nguyen, Izadi & Lovell 2012, eq. for sigma_L): each output pixel takes
   the depth of the pixel at a Gaussian offset (rounded, clamped to the image), which
   blurs depth edges.
4. Axial noise (same paper): Gaussian sigma_z(z, theta) added to z, per pixel in the
   independent model; in the correlated model (the default) partly as a smooth field.
5. Disparity quantisation: d = f b / z in 1/8 px steps (Kinect v1, docs/architecture.md), after the
   fixed disparity pattern (default on) is added to d.
6. Range cut [min_range_m, max_range_m] on the measured depth.
7. Dropouts rising linearly with theta between 70 and 85 degrees, plus an optional
   uniform dropout rate.

The correlated model. A Kinect v1 does not measure depth pixel by pixel: it block-matches
the projected speckle pattern over a correlation window (9 x 9 or 9 x 7 px, to 1/8 px;
Konolige & Mihelich, ROS kinect_calibration technical description), so its depth is
locally smooth, shows wide bands of one disparity step on a flat wall, and carries a fixed
spatial distortion of its own (Smisek, Jancosek & Pajdla 2011; Herrera, Kannala & Heikkila
2012; Clarkson et al. 2013: a plane filling the view comes back non-planar in a pattern
that stays with the sensor). Two terms model this:

- Spatially correlated axial noise (``correlated``): Nguyen's sigma_z = a + qz (+ the
  grazing term), qz = b (z - z0)^2. Our reading of its two terms: the range term qz, which
  grows like the disparity error (z^2), is the block-matched error and is correlated; the
  constant a is per pixel. The split keeps sigma_z per pixel: the share
  qz^2 / (a^2 + qz^2) of sigma_z^2 goes to a unit-variance Gaussian field of correlation
  length ``corr_length_px`` (autocorrelation exp(-(r / L)^2)), new every frame; the rest
  stays independent from pixel to pixel. At 1 m the field holds 25 % of the variance, at
  3 m 99 %. L = 32 px: the sources give no length; the correlation window (9 px) is its
  lower bound. FSPF with BV2012 Table I's parameters, which BV2012 ran on real frames to
  the sensor's range, finds planes on a wall at 3.5 m from L = 16 px on, after sampling
  7,000-13,000 of its 20,000 neighbourhoods, and after 650-1,100 from L = 32 px on
  (docs/kinect_noise.md has the measurements); 32 px is the value we took.
- Fixed pattern (``pattern``), the temporal term: a smooth disparity offset per pixel,
  the same in every frame of a sensor (``pattern_seed``), added to d before the 1/8 px
  rounding, so its depth effect grows like z^2 / (f b). Standard deviation
  ``pattern_sigma_px`` = 0.09 px, fitted on the mapping_wall scenario (seed 5) to PlaneMap's
  Table III (a real Kinect facing a wall at 1.06 m and 1.56 m: 3.9 / 8.8 mm with RANSAC,
  2.5 / 7.4 mm with Hough), whose spread is about twice Nguyen's sigma_z; correlation
  length ``pattern_length_px`` = 96 px (our choice: the sources show the pattern over the
  whole view but give no length). With it, errors are correlated in time in part: at a
  pixel, the pattern's share of the variance.

``correlated=False, pattern=False`` is the independent model.

Randomness is counter based: pixel i of a frame draws one 64-bit word, a SplitMix64 hash
of (seed, i) (Steele, Lea & Flood 2014), whose bits give the two lateral offsets (a
2048-quantile normal table), the axial normal (a 1024-layer ziggurat, Marsaglia & Tsang
2000) and the dropout uniform. The smooth fields draw their coarse-grid normals from words
of keys derived from the frame's seed (the correlated field) and from ``pattern_seed`` (the
pattern). The output depends only on the inputs, the config and the seed (never on call
history, global RNG state or the thread count): same seed, same image, bit for bit.

Speed: per row, vectorised float32 loops (normals, incidence angles, the final arithmetic)
and lean scalar loops (table lookups, gathers, the shadow scan). The image is split into
``cfg.threads`` row blocks run on threads with the GIL released; each block computes its
own halo rows, so blocks need no synchronisation. ``python bench/noise_bench.py`` times it.

Choices where the sources leave room: an output pixel whose own input is invalid stays 0
(holes are not filled by the lateral jitter; a shadowed pixel can take a lit neighbour's
depth); sigma_z and the dropout probability are those of the source pixel (its clean
depth and theta); sigma_L is in pixels of a ``focal_px`` camera and scales with
``intr.fx``; the range cut applies to the measured (noisy, quantised) depth; theta is
clamped to 89 degrees in the closed forms. Nguyen et al. measured sigma_z on the sensor's
quantised output; as specified for this module we still add quantisation on top
(variance about sigma_z^2 + step^2 / 12).

Modules: ``config`` (the parameters and closed forms), ``draws`` (the counter-based words
and normals), ``fields`` (the smooth fields and the fixed pattern), ``geometry`` and
``kernels`` (the numba kernels), ``blocks`` (the row blocks on threads) and ``apply``
(the entry points re-exported here).
"""

from sim.simulator.kinect_noise.apply import apply_kinect_noise, incidence_angle
from sim.simulator.kinect_noise.config import (
    THETA_MAX_RAD,
    KinectNoiseConfig,
    axial_sigma_m,
    depth_step_m,
    dropout_probability,
    lateral_sigma_px,
)
from sim.simulator.kinect_noise.fields import pattern_disparity_px, smooth_field

__all__ = [
    "THETA_MAX_RAD",
    "KinectNoiseConfig",
    "apply_kinect_noise",
    "axial_sigma_m",
    "depth_step_m",
    "dropout_probability",
    "incidence_angle",
    "lateral_sigma_px",
    "pattern_disparity_px",
    "smooth_field",
]
