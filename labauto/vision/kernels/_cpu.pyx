# cython: language_level=3
"""Which vector level this x86-64 CPU has, so that labauto loads the kernels built for it."""

cdef extern from *:
    """
    static int labauto_x86_64_v3(void) {
    #if (defined(__x86_64__) || defined(_M_X64)) && defined(__GNUC__)
        __builtin_cpu_init();
    #if defined(__clang__) || __GNUC__ < 12
        return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")
            && __builtin_cpu_supports("bmi2") && __builtin_cpu_supports("avx");
    #else
        return __builtin_cpu_supports("x86-64-v3");
    #endif
    #else
        return 0;
    #endif
    }
    """
    int _x86_64_v3 "labauto_x86_64_v3"() noexcept nogil


def x86_64_v3() -> bool:
    """Whether the CPU runs code built for ``-march=x86-64-v3`` (AVX2, FMA, BMI2, ...)."""
    return _x86_64_v3() != 0
