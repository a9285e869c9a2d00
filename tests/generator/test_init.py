"""surfgen.generator's set-up of numba: 512-bit vectors on AVX-512 CPUs."""

from __future__ import annotations

import os

from llvmlite import binding

from surfgen.generator import wide_vector_features

AVX512 = "+sse2,+avx,+avx2,+fma,+avx512f,+avx512bw,+avx512dq,+avx512vl"
AVX2 = "+sse2,+avx,+avx2,+fma,-avx512f,-avx512bw"


def test_avx512_cpus_turn_off_llvms_preference_for_256_bit_vectors():
    assert wide_vector_features({}, AVX512) == AVX512 + ",-prefer-256-bit"


def test_nothing_changes_without_avx512_or_when_the_user_chose():
    assert wide_vector_features({}, AVX2) is None
    assert wide_vector_features({}, "") is None
    assert wide_vector_features({"NUMBA_CPU_FEATURES": "+avx2"}, AVX512) is None
    assert wide_vector_features({"NUMBA_ENABLE_AVX": "0"}, AVX512) is None
    assert wide_vector_features({"NUMBA_ENABLE_AVX": "1"}, AVX512) is not None


def test_numba_was_given_the_features_on_this_machine():
    # Importing surfgen.generator set NUMBA_CPU_FEATURES before numba read its configuration:
    # on an AVX-512 host the host's features without prefer-256-bit, elsewhere nothing (or the
    # user's own setting, left alone).
    import numba

    host = binding.get_host_cpu_features().flatten()
    if "+avx512f" in host.split(","):
        assert os.environ["NUMBA_CPU_FEATURES"] == numba.config.CPU_FEATURES
        assert numba.config.CPU_FEATURES.endswith(",-prefer-256-bit")
        assert set(numba.config.CPU_FEATURES.split(",")) >= set(host.split(","))
    else:
        assert "-prefer-256-bit" not in (numba.config.CPU_FEATURES or "")
