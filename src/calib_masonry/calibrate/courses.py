"""The scale from the masonry's module: how many courses of a known height the wall is tall.

A brick wall's bed joints repeat at the course height (a brick's height and its joint). With the
mean course height given (``--course-height M``, from the brick's format or one tape measurement
over ten courses), the number of courses the photo shows fixes the wall's height, so the scale,
without measuring the wall itself.

The orthophoto of a first fit (whatever its scale: only its shape matters) is reduced to the
profile of its rows (the mean lightness over the middle 80 % of the width, less a running mean a
few courses wide). The profile's autocorrelation repeats at the course height; the period is the
slope of the first few autocorrelation peaks' positions against their order (a line through the
origin, by least squares), and its standard error comes from that regression. The height is the
number of courses (rows over period) times the course height; its sigma combines the course
height's and the period's. A profile without a clear repeat (irregular stones, a plastered wall) is
refused: the module says nothing there.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from ..errors import FitFailed

__all__ = ["course_period", "course_scale"]

#: the autocorrelation at the first period must reach this to count as courses
MIN_PEAK = 0.25


def course_period(profile: np.ndarray, *, min_period: float = 4.0) -> tuple[float, float, float]:
    """The repeat of a 1-D profile (rows): ``(period, its standard error, the autocorrelation at it)``.
    Raises FitFailed without a clear repeat."""
    p = np.asarray(profile, dtype=np.float64)
    n = len(p)
    p = p - p.mean()
    if n < 8 * min_period or not np.any(p):
        raise FitFailed("the wall's rows are too few to find its courses")
    spec = np.fft.rfft(p, 2 * n)
    ac = np.fft.irfft(spec * np.conj(spec))[:n]
    ac /= ac[0]
    # the first period: the highest autocorrelation peak between min_period and a third of the rows
    lo, hi = int(math.ceil(min_period)), n // 3
    peaks = [k for k in range(lo, hi) if ac[k] >= ac[k - 1] and ac[k] >= ac[k + 1] and ac[k] > 0]
    if not peaks:
        raise FitFailed("no repeat found in the wall's rows (no courses)")
    k0 = max(peaks, key=lambda k: ac[k])
    # the first harmonic is the period when a strong peak at half its lag exists (every other
    # course alike in a bond pattern would double it)
    half = [k for k in peaks if abs(k - k0 / 2) <= max(1.0, 0.1 * k0) and ac[k] > 0.6 * ac[k0]]
    if half:
        k0 = max(half, key=lambda k: ac[k])
    if ac[k0] < MIN_PEAK:
        raise FitFailed(f"the wall's rows repeat only weakly (autocorrelation {ac[k0]:.2f} at the best lag)")

    def refine(k: int) -> float:  # parabolic peak position
        a, b, c = ac[k - 1], ac[k], ac[k + 1]
        den = a - 2 * b + c
        return k + (0.5 * (a - c) / den if den < -1e-12 else 0.0)

    pos, order = [], []
    for m in range(1, 8):
        guess = m * refine(k0)
        k = int(round(guess))
        if k + 1 >= n or k - 1 < 1:
            break
        window = range(max(1, k - 2), min(n - 1, k + 3))
        k = max(window, key=lambda j: ac[j])
        if not (ac[k] >= ac[k - 1] and ac[k] >= ac[k + 1]) or ac[k] < 0.5 * MIN_PEAK:
            break
        pos.append(refine(k))
        order.append(m)
    pos, order = np.array(pos), np.array(order, dtype=np.float64)
    period = float(pos @ order / (order @ order))
    if len(pos) >= 3:
        resid = pos - period * order
        se = math.sqrt(float(resid @ resid) / (len(pos) - 1) / float(order @ order))
    else:
        se = 0.25 / max(len(pos), 1)  # a quarter row over the peaks used
    return period, max(se, 0.02 * period / max(len(pos), 1)), float(ac[k0])


def course_scale(ortho: np.ndarray, course_height_m: float, course_height_sigma_m: float) -> dict:
    """The wall's height from its courses: the wall's orthophoto ``ortho`` (grey, its rows the
    wall's height) reduced to a row profile, its period, and the course height (with its sigma).
    Returns the height, its sigma, the number of courses and the autocorrelation at the period.
    Raises :class:`~calib_masonry.errors.FitFailed` where no period stands out."""
    c = float(course_height_m)
    c_sigma = float(course_height_sigma_m)
    cols = ortho.shape[1]
    mid = ortho[:, int(0.1 * cols) : max(int(0.1 * cols) + 1, int(0.9 * cols))]
    profile = mid.mean(axis=1).astype(np.float64)
    # less a running mean about eight percent of the height (lighting and weathering vary slowly)
    profile = profile - ndimage.uniform_filter1d(profile, max(3, int(0.08 * len(profile))), mode="nearest")
    period, se, peak = course_period(profile)
    courses = len(profile) / period
    height = courses * c
    rel = math.hypot(c_sigma / c, se / period)
    return {
        "course_height_m": c,
        "course_height_sigma_m": c_sigma,
        "courses": courses,
        "period_rows": period,
        "period_se_rows": se,
        "autocorrelation": peak,
        "height_m": height,
        "height_sigma_m": height * rel,
    }
