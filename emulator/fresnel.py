"""The Fresnel integrals S(x) and C(x) in numpy, as scipy.special.fresnel computes them.

The clothoid corners of every scenario need them before the emulator is ready, and
importing scipy.special costs a process about 0.3 CPU-s (docs/performance.md). This is
Cephes' ``fresnl`` as scipy vendors it (xsf, include/xsf/cephes/fresnl.h: Stephen L.
Moshier's coefficients, Cephes Math Library 2.1, 1989; sinpi and cospi of
include/xsf/cephes/trig.h): the same coefficients, branches and order of operations, one
rounding per multiply and add as in scipy's build, so the values are scipy's to the bit
and the golden recordings made with scipy stay byte-identical
(tests/emulator/test_fresnel.py, with scipy as the oracle only there).
"""
from __future__ import annotations

import math

import numpy as np

# S(x) for small x: polevl(x^4, SN) / p1evl(x^4, SD)
SN = (-2.99181919401019853726E3, 7.08840045257738576863E5, -6.29741486205862506537E7,
      2.54890880573376359104E9, -4.42979518059697779103E10, 3.18016297876567817986E11)
SD = (2.81376268889994315696E2, 4.55847810806532581675E4, 5.17343888770096400730E6,
      4.19320245898111231129E8, 2.24411795645340920940E10, 6.07366389490084639049E11)
# C(x) for small x: polevl(x^4, CN) / polevl(x^4, CD)
CN = (-4.98843114573573548651E-8, 9.50428062829859605134E-6, -6.45191435683965050962E-4,
      1.88843319396703850064E-2, -2.05525900955013891793E-1, 9.99999999999999998822E-1)
CD = (3.99982968972495980367E-12, 9.15439215774657478799E-10, 1.25001862479598821474E-7,
      1.22262789024179030997E-5, 8.68029542941784300606E-4, 4.12142090722199792936E-2,
      1.00000000000000000118E0)
# the auxiliary functions f(x) and g(x) of the asymptotic series for large x
FN = (4.21543555043677546506E-1, 1.43407919780758885261E-1, 1.15220955073585758835E-2,
      3.45017939782574027900E-4, 4.63613749287867322088E-6, 3.05568983790257605827E-8,
      1.02304514164907233465E-10, 1.72010743268161828879E-13, 1.34283276233062758925E-16,
      3.76329711269987889006E-20)
FD = (7.51586398353378947175E-1, 1.16888925859191382142E-1, 6.44051526508858611005E-3,
      1.55934409164153020873E-4, 1.84627567348930545870E-6, 1.12699224763999035261E-8,
      3.60140029589371370404E-11, 5.88754533621578410010E-14, 4.52001434074129701496E-17,
      1.25443237090011264384E-20)
GN = (5.04442073643383265887E-1, 1.97102833525523411709E-1, 1.87648584092575249293E-2,
      6.84079380915393090172E-4, 1.15138826111884280931E-5, 9.82852443688422223854E-8,
      4.45344415861750144738E-10, 1.08268041139020870318E-12, 1.37555460633261799868E-15,
      8.36354435630677421531E-19, 1.86958710162783235106E-22)
GD = (1.47495759925128324529E0, 3.37748989120019970451E-1, 2.53603741420338795122E-2,
      8.14679107184306179049E-4, 1.27545075667729118702E-5, 1.04314589657571990585E-7,
      4.60680728146520428211E-10, 1.10273215066240270757E-12, 1.38796531259578871258E-15,
      8.39158816283118707363E-19, 1.86958710162783236342E-22)

SMALL_X2 = 2.5625  # x^2 below this: the power series
HUGE_X = 36974.0  # x above this: the leading term of the asymptotic expansion


def polevl(x: np.ndarray, coef) -> np.ndarray:
    """coef[0] x^N + ... + coef[N], by Horner's rule from the highest power (Cephes' polevl)."""
    ans = np.full_like(x, coef[0])
    for c in coef[1:]:
        ans = ans * x + c
    return ans


def p1evl(x: np.ndarray, coef) -> np.ndarray:
    """x^N + coef[0] x^(N-1) + ... + coef[N-1] (Cephes' p1evl: the leading 1 left out)."""
    ans = x + coef[0]
    for c in coef[1:]:
        ans = ans * x + c
    return ans


def sinpi(x: np.ndarray) -> np.ndarray:
    """sin(pi x) for x >= 0, reduced modulo 2 first as xsf's sinpi does."""
    r = np.fmod(x, 2.0)
    return np.where(r < 0.5, np.sin(math.pi * r),
                    np.where(r > 1.5, np.sin(math.pi * (r - 2.0)), -np.sin(math.pi * (r - 1.0))))


def cospi(x: np.ndarray) -> np.ndarray:
    """cos(pi x) for x >= 0, reduced modulo 2 first as xsf's cospi does (+0 at r = 1/2)."""
    r = np.fmod(x, 2.0)
    out = np.where(r < 1.0, -np.sin(math.pi * (r - 0.5)), np.sin(math.pi * (r - 1.5)))
    return np.where(r == 0.5, 0.0, out)


def fresnel(z) -> tuple[np.ndarray, np.ndarray]:
    """(S(z), C(z)) elementwise for real *z*, as ``scipy.special.fresnel(z)`` gives them."""
    z = np.asarray(z, dtype=float)
    x = np.abs(z)
    ss, cc = np.empty_like(x), np.empty_like(x)
    with np.errstate(all="ignore"):  # overflow and NaN give NaN silently, as in scipy
        x2 = x * x
        small = x2 < SMALL_X2
        if small.any():
            xs, x2s = x[small], x2[small]
            t = x2s * x2s
            ss[small] = xs * x2s * polevl(t, SN) / p1evl(t, SD)
            cc[small] = xs * polevl(t, CN) / polevl(t, CD)
        huge = x > HUGE_X
        if huge.any():
            xh = x[huge]
            half = xh * xh / 2
            cc[huge] = 0.5 + 1 / (math.pi * xh) * sinpi(half)
            ss[huge] = 0.5 - 1 / (math.pi * xh) * cospi(half)
        large = ~small & ~huge  # NaN falls here and stays NaN, as in scipy
        if large.any():
            xl, x2l = x[large], x2[large]
            t = math.pi * x2l
            u = 1.0 / (t * t)
            t = 1.0 / t
            f = 1.0 - u * polevl(u, FN) / p1evl(u, FD)
            g = t * polevl(u, GN) / p1evl(u, GD)
            c, s = cospi(x2l / 2), sinpi(x2l / 2)
            t = math.pi * xl
            cc[large] = 0.5 + (f * s - g * c) / t
            ss[large] = 0.5 - (f * c + g * s) / t
        inf = np.isinf(x)
        ss[inf] = cc[inf] = 0.5
    negative = z < 0.0
    ss[negative] = -ss[negative]
    cc[negative] = -cc[negative]
    return ss, cc
