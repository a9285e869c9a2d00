"""The constants and polynomial coefficients of surfgen's exp, log, pow and the functions built
from them (:mod:`surfgen.generator.elementary.explog`; coefficients from
``tools/explog_coefficients.py``). numba freezes them into the kernels that read them.
"""

from __future__ import annotations

import math

# ----------------------------------------------------------------------------- constants

INF = math.inf
NAN = math.nan  # 0x7ff8000000000000
SHIFT = 6755399441055744.0  # 1.5 * 2^52: x + SHIFT rounds x to an integer held in the low bits
SHIFT_BITS = 0x4338000000000000
TWO52 = 4503599627370496.0
TWO53 = 9007199254740992.0
SPLITTER = 134217729.0  # 2^27 + 1 (Veltkamp)
MASK26 = -(1 << 27)  # keep sign, exponent and 25 explicit mantissa bits: 26 significant bits
MASK27 = -(1 << 26)
INV_LN2 = 1.4426950408889634
LN2_H = 0.6931471805598903  # ln 2 rounded to 42 bits: k * LN2_H is exact for |k| < 2^11
LN2_L = 5.497923018708371e-14
LN2_FULL_H = 0.6931471805599453
LN2_FULL_L = 2.3190468138462996e-17
INV_LN10_H = 0.4342944819032518
INV_LN10_L = 1.098319650216765e-17
THIRD = 0.3333333333333333
SQRT_HALF_BITS = 0x3FE6A09E667F3BCD
TINY_NORMAL = 2.2250738585072014e-308
TWO54 = 18014398509481984.0
TWO28 = 268435456.0
TWO_M28 = 3.725290298461914e-09

# log(j/8), j = 6..11, as LCjH + LCjL with LCjH a multiple of 2^-42 (so that e*LN2_H + LCjH
# is exact) and LCjL the rest rounded to double.
LC6H, LC6L = -0.28768207245184385, 6.292357389008195e-14
LC7H, LC7L = -0.13353139262449076, -3.1859736349078334e-14
LC9H, LC9L = 0.11778303565643, -4.654729747598445e-14
LC10H, LC10L = 0.22314355131425145, -4.169796584527195e-14
LC11H, LC11L = 0.31845373111855224, -1.7625431312172662e-14

# Q(r) = (e^r - 1 - r - r^2/2)/r^3 on |r| <= 0.3467, degree 9, |r^3 dQ| < 2^-60.3.
EQ0 = 0.16666666666666669
EQ1 = 0.041666666666666664
EQ2 = 0.008333333333330055
EQ3 = 0.0013888888888886548
EQ4 = 0.00019841269863088255
EQ5 = 2.4801587317169235e-05
EQ6 = 2.7557268406190795e-06
EQ7 = 2.7557282931125736e-07
EQ8 = 2.51004110820149e-08
EQ9 = 2.091125490208877e-09

# H(q) = (3 atanh(sqrt q)/sqrt q - 3 - q)/q^2 on q <= 0.04^2, degree 4, |q^2 dH| < 2^-73.
LH0 = 0.6
LH1 = 0.4285714285713001
LH2 = 0.3333333339754841
LH3 = 0.2727261493317481
LH4 = 0.23157106960641805
# (2/3) H for the plain log: 2 atanh(s) = 2s + s w (2/3 + w (2/3) H(w)).
TWO_THIRDS = 2.0 / 3.0
LK0 = TWO_THIRDS * LH0
LK1 = TWO_THIRDS * LH1
LK2 = TWO_THIRDS * LH2
LK3 = TWO_THIRDS * LH3
LK4 = TWO_THIRDS * LH4

# S(w) = (sinh(sqrt w) - sqrt w)/w^1.5 on w <= 0.5^2, degree 6, |w^1.5 dS| < 2^-59.6.
SS0 = 0.16666666666666666
SS1 = 0.008333333333333333
SS2 = 0.00019841269841269893
SS3 = 2.755731922385946e-06
SS4 = 2.5052108529916113e-08
SS5 = 1.605895909905728e-10
SS6 = 7.671802234064814e-13

# T(w) = (tanh(sqrt w) - sqrt w)/w^1.5 on w <= 0.125^2, degree 6, |w^1.5 dT| < 2^-64.6.
TT0 = -0.3333333333333333
TT1 = 0.13333333333333322
TT2 = -0.053968253968151046
TT3 = 0.021869488496608067
TT4 = -0.008863228290024993
TT5 = 0.0035914470237015917
TT6 = -0.0014239969035219852
