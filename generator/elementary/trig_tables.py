"""The constants and coefficient tables of surfgen's sin, cos, tan, asin, acos, atan and
atan2 (:mod:`surfgen.generator.elementary.trig`): pi/2 in parts, 2/pi's digits, the minimax
polynomials (``tools/trig_coefficients.py``). numba freezes them into the kernels that read them.
"""

from __future__ import annotations

import numpy as np

# ----------------------------------------------------------------------------- constants

NAN = float("nan")
INF = float("inf")
_RND = 6755399441055744.0  # 1.5 * 2**52: (v + _RND) - _RND rounds v (|v| < 2**51) to an integer
_SPLIT = 134217729.0  # 2**27 + 1, Veltkamp/Dekker splitting
_TINY_TRIG = 2.0**-27  # below this sin(x) and tan(x) round to x (and keep the sign of zero)

# Fast range of the trigonometric reduction: |x| <= 2**23 keeps |n| < 2**24 for pi/4 steps.
TRIG_FAST_LIMIT = 8388608.0

_TWO_OVER_PI = 0.6366197723675814
_FOUR_OVER_PI = 1.2732395447351628
# pi/2 = _C1 + _C2 + _C3 + _C4 (+ 2e-43): three 29-bit parts (n * part is exact) and the rest.
_C1 = 1.570796325802803
_C2 = 9.920935774287987e-10
_C3 = 2.2517417706346578e-18
_C4 = 3.5215598651832e-27

# Double-double constants (hi, lo).
_PIO2_HI = 1.5707963267948966
_PIO2_LO = 6.123233995736766e-17
_PI_HI = 3.141592653589793
_PI_LO = 1.2246467991473532e-16
_PIO4_HI = 0.7853981633974483
_PIO4_LO = 3.061616997868383e-17
_ATAN_HALF_HI = 0.4636476090008061
_ATAN_HALF_LO = 2.2698777452961687e-17
_ATAN_TWO_HI = 1.1071487177940904
_ATAN_TWO_LO = 9.40447137356638e-17

# 2/pi in hexadecimal, 56 digits of 24 bits (1344 bits: enough for |x| up to 2**1024 with
# 9 digits = 216 bits below the binary point). A test checks it against mpmath.
_TWO_OVER_PI_HEX = (
    "A2F9836E4E441529FC2757D1F534DDC0DB6295993C439041FE5163ABDEBBC561B7246E3A424DD2E0"
    "06492EEA09D1921CFE1DEB1CB129A73EE88235F52EBB4484E99C7026B45F7E413991D639835339F4"
    "9C845F8BBDF9283B1FF897FFDE05980FEF2F118B5A0A6D1F6D367ECF27CB09B74F463F669E5FEA2D"
    "7527BAC7EBE5F17B3D0739F78A5292EA6BFB5FB11F8D5D0856033046FC7B6BABF0CFBC209AF4361D"
    "A9E391615EE61B08"
)
_F = np.array(
    [float(int(_TWO_OVER_PI_HEX[6 * i : 6 * i + 6], 16)) for i in range(56)], dtype=np.float64
)
_NF = 56

# Minimax coefficients (tools/trig_coefficients.py; relative error of the double coefficients).
# SIN: (sin y - y)/y^3 ~ P(z), degree 6 in z on [0, (pi/4)^2], max relative error 2^-53.96
_S0 = -0.16666666666666666
_S1 = 0.008333333333333331
_S2 = -0.00019841269841265025
_S3 = 2.7557319219311545e-06
_S4 = -2.5052106223756418e-08
_S5 = 1.6058530358304306e-10
_S6 = -7.586628537108794e-13
# COS: (cos y - 1 + z/2)/z^2 ~ P(z), degree 6 in z on [0, (pi/4)^2], max relative error 2^-53.99
_K0 = 0.041666666666666664
_K1 = -0.0013888888888888887
_K2 = 2.4801587301584632e-05
_K3 = -2.7557319221392475e-07
_K4 = 2.0876755787810643e-09
_K5 = -1.1470460411538402e-11
_K6 = 4.7458459095111584e-14
# TAN: (tan y - y)/y^3 ~ P(z), degree 10 in z on [0, (pi/8)^2], max relative error 2^-53.98
_T0 = 0.3333333333333333
_T1 = 0.1333333333333333
_T2 = 0.05396825396825912
_T3 = 0.02186948853563535
_T4 = 0.008863235556764073
_T5 = 0.003592127228321649
_T6 = 0.0014558495097747608
_T7 = 0.000589846429091682
_T8 = 0.00024051180051042978
_T9 = 9.044154256713682e-05
_T10 = 5.585806408573994e-05
# ASIN: (asin x - x)/x^3 ~ P(z), degree 13 in z on [0, 1/4], max relative error 2^-53.97
_A0 = 0.16666666666666666
_A1 = 0.07500000000000125
_A2 = 0.04464285714253505
_A3 = 0.030381944477026034
_A4 = 0.02237215737477593
_A5 = 0.017352818420701247
_A6 = 0.013963747020434432
_A7 = 0.01156684716425047
_A8 = 0.009618729468019399
_A9 = 0.009336720020990662
_A10 = 0.002981078356138755
_A11 = 0.019707461794546254
_A12 = -0.019455095000504977
_A13 = 0.029743704563521073
# ATAN: (atan t - t)/t^3 ~ P(z), degree 11 in z on [0, (7/16)^2], max relative error 2^-53.76
_U0 = -0.3333333333333333
_U1 = 0.19999999999999424
_U2 = -0.14285714285569598
_U3 = 0.11111111096871155
_U4 = -0.09090908365001396
_U5 = 0.0769228578295156
_U6 = -0.06666245375190637
_U7 = 0.05876980023758304
_U8 = -0.05216889502494796
_U9 = 0.04493073489321706
_U10 = -0.033145998293442634
_U11 = 0.01479011397139272

# atan2: finite non-zero operands outside [2**-500, 2**500] take the slow path (scaling).
_A2_LO = 2.0**-500
_A2_HI = 2.0**500
_ATAN_CLAMP = 2.0**60  # atan(x) rounds to pi/2 for |x| >= 2**60
