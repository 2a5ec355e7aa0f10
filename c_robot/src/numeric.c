/* The portable numeric kernel: fdlibm's algorithms in plain IEEE arithmetic, exactly as
   docs/kernel.md and bestofn_swarm/wire/numeric.py write them (compile with -ffp-contract=off). */
#include "numeric.h"

#include "limits.h"

#include <math.h>
#include <string.h>

#define INV_PIO2 0x1.45f306dc9c883p-1
#define PIO2_1 0x1.921fb544p+0
#define PIO2_2 0x1.0b4611a6p-34
#define PIO2_2T 0x1.3198a2e037073p-69
#define PI_LO 0x1.1a62633145c07p-53
#define S1 (-0x1.5555555555549p-3)
#define S2 0x1.111111110f8a6p-7
#define S3 (-0x1.a01a019c161d5p-13)
#define S4 0x1.71de357b1fe7dp-19
#define S5 (-0x1.ae5e68a2b9cebp-26)
#define S6 0x1.5d93a5acfd57cp-33
#define C1 0x1.555555555554cp-5
#define C2 (-0x1.6c16c16c15177p-10)
#define C3 0x1.a01a019cb159p-16
#define C4 (-0x1.27e4f809c52adp-22)
#define C5 0x1.1ee9ebdb4b1c4p-29
#define C6 (-0x1.8fae9be8838d4p-37)
#define ATAN_HI_0 0x1.dac670561bb4fp-2
#define ATAN_HI_1 0x1.921fb54442d18p-1
#define ATAN_HI_2 0x1.f730bd281f69bp-1
#define ATAN_HI_3 0x1.921fb54442d18p+0
#define ATAN_LO_0 0x1.a2b7f222f65e2p-56
#define ATAN_LO_1 0x1.1a62633145c07p-55
#define ATAN_LO_2 0x1.007887af0cbbdp-56
#define ATAN_LO_3 0x1.1a62633145c07p-54
#define AT0 0x1.555555555550dp-2
#define AT1 (-0x1.999999998ebc4p-3)
#define AT2 0x1.24924920083ffp-3
#define AT3 (-0x1.c71c6fe231671p-4)
#define AT4 0x1.745cdc54c206ep-4
#define AT5 (-0x1.3b0f2af749a6dp-4)
#define AT6 0x1.10d66a0d03d51p-4
#define AT7 (-0x1.dde2d52defd9ap-5)
#define AT8 0x1.97b4b24760debp-5
#define AT9 (-0x1.2b4442c6a6c2fp-5)
#define AT10 0x1.0ad3ae322da11p-6
#define ATAN_BIG 0x1p66
#define LN2_HI 0x1.62e42feep-1
#define LN2_LO 0x1.a39ef35793c76p-33
#define INV_LN2 0x1.71547652b82fep+0
#define EXP_OVERFLOW 0x1.62e42fefa39efp+9
#define EXP_UNDERFLOW (-0x1.74910d52d3051p+9)
#define P1 0x1.555555555553ep-3
#define P2 (-0x1.6c16c16bebd93p-9)
#define P3 0x1.1566aaf25de2cp-14
#define P4 (-0x1.bbd41c5d26bf1p-20)
#define P5 0x1.6376972bea4d0p-25
#define SQRT_HALF 0x1.6a09ep-1
#define LG1 0x1.5555555555593p-1
#define LG2 0x1.999999997fa04p-2
#define LG3 0x1.2492494229359p-2
#define LG4 0x1.c71c51d8e78afp-3
#define LG5 0x1.7466496cb03dep-3
#define LG6 0x1.39a09d078c69fp-3
#define LG7 0x1.2f112df3e5244p-3
#define INV_TWO_PI 0x1.45f306dc9c883p-3
#define TWO_PI_HI (4.0 * PIO2_1)
#define TWO_PI_LO 0x1.0b4611a626331p-32

static void reduce(double x, double *fn_out, double *y0, double *y1) {
    double fn = floor(x * INV_PIO2 + 0.5);
    if (fn == 0.0) {
        *y0 = x;
        *y1 = 0.0;
    } else {
        double r = x - fn * PIO2_1;
        double w = fn * PIO2_2;
        double t = r;
        r = t - w;
        w = fn * PIO2_2T - ((t - r) - w);
        *y0 = r - w;
        *y1 = (r - *y0) - w;
    }
    *fn_out = fn;
}

int nk_sincos(double x, double *sine, double *cosine) {
    if (!(-NK_MAX_ANGLE <= x && x <= NK_MAX_ANGLE)) return -1;
    double fn, y0, y1;
    reduce(x, &fn, &y0, &y1);
    double z = y0 * y0;
    double w = z * z;
    double v = z * y0;
    double r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6);
    double s = y0 - ((z * (0.5 * y1 - v * r) - y1) - v * S1);
    r = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6));
    double hz = 0.5 * z;
    w = 1.0 - hz;
    double c = w + (((1.0 - w) - hz) + (z * r - y0 * y1));
    long long n = (long long)fn;
    switch ((int)(n & 3)) {
    case 0: *sine = s; *cosine = c; break;
    case 1: *sine = c; *cosine = -s; break;
    case 2: *sine = -s; *cosine = -c; break;
    default: *sine = -c; *cosine = s; break;
    }
    return 0;
}

double nk_sin(double x) {
    double s, c;
    if (nk_sincos(x, &s, &c) != 0) return NAN;
    return s;
}

double nk_cos(double x) {
    /* sincos(x)[1]: the same bits as the reference's specialised cos (its kernels are the
       same expressions). */
    double s, c;
    if (nk_sincos(x, &s, &c) != 0) return NAN;
    return c;
}

static double atan2_special(double y, double x) {
    if (isnan(x) || isnan(y)) return x + y;
    int x_negative = copysign(1.0, x) < 0.0;
    if (y == 0.0) return x_negative ? copysign(NK_PI, y) : y;
    if (x == 0.0) return copysign(NK_HALF_PI, y);
    if (isinf(x)) {
        double z;
        if (isinf(y))
            z = x_negative ? 3.0 * NK_PI / 4.0 : NK_PI / 4.0;
        else
            z = x_negative ? NK_PI : 0.0;
        return copysign(z, y);
    }
    return copysign(NK_HALF_PI, y);
}

double nk_atan2(double y, double x) {
    double ax = fabs(x), ay = fabs(y);
    if (!(0.0 < ax && ax < INFINITY && 0.0 < ay && ay < INFINITY)) return atan2_special(y, x);
    double a = ay / ax;
    double z;
    if (a >= ATAN_BIG) {
        z = ATAN_HI_3;
    } else if (a < 0.4375) {
        double zz = a * a;
        double w = zz * zz;
        double s1 = zz * (AT0 + w * (AT2 + w * (AT4 + w * (AT6 + w * (AT8 + w * AT10)))));
        double s2 = w * (AT1 + w * (AT3 + w * (AT5 + w * (AT7 + w * AT9))));
        z = a - a * (s1 + s2);
    } else {
        double hi, lo, t;
        if (a < 0.6875) {
            hi = ATAN_HI_0; lo = ATAN_LO_0; t = (2.0 * a - 1.0) / (2.0 + a);
        } else if (a < 1.1875) {
            hi = ATAN_HI_1; lo = ATAN_LO_1; t = (a - 1.0) / (a + 1.0);
        } else if (a < 2.4375) {
            hi = ATAN_HI_2; lo = ATAN_LO_2; t = (a - 1.5) / (1.0 + 1.5 * a);
        } else {
            hi = ATAN_HI_3; lo = ATAN_LO_3; t = -1.0 / a;
        }
        double zz = t * t;
        double w = zz * zz;
        double s1 = zz * (AT0 + w * (AT2 + w * (AT4 + w * (AT6 + w * (AT8 + w * AT10)))));
        double s2 = w * (AT1 + w * (AT3 + w * (AT5 + w * (AT7 + w * AT9))));
        z = hi - ((t * (s1 + s2) - lo) - t);
    }
    if (x < 0.0) z = NK_PI - (z - PI_LO);
    return y > 0.0 ? z : -z;
}

double nk_atan(double x) {
    if (isnan(x) || x == 0.0) return x;
    if (isinf(x)) return copysign(ATAN_HI_3, x);
    return copysign(nk_atan2(fabs(x), 1.0), x);
}

double nk_exp(double x) {
    if (isnan(x)) return x;
    if (x > EXP_OVERFLOW) return INFINITY;
    if (x < EXP_UNDERFLOW) return 0.0;
    double k = floor(x * INV_LN2 + 0.5);
    double hi = x - k * LN2_HI;
    double lo = k * LN2_LO;
    double r = hi - lo;
    double rr = r * r;
    double c = r - rr * (P1 + rr * (P2 + rr * (P3 + rr * (P4 + rr * P5))));
    double y = 1.0 + ((r * c / (2.0 - c) - lo) + hi);
    return ldexp(y, (int)k);
}

double nk_log(double x) {
    if (isnan(x) || x == INFINITY) return x;
    if (x <= 0.0) return x == 0.0 ? -INFINITY : NAN;
    int k;
    double m = frexp(x, &k);
    if (m < SQRT_HALF) {
        m = 2.0 * m;
        k -= 1;
    }
    double f = m - 1.0;
    double hfsq = 0.5 * f * f;
    double s = f / (2.0 + f);
    double z = s * s;
    double w = z * z;
    double t1 = w * (LG2 + w * (LG4 + w * LG6));
    double t2 = z * (LG1 + w * (LG3 + w * (LG5 + w * LG7)));
    double r = t2 + t1;
    double dk = (double)k;
    return (((s * (hfsq + r) + dk * LN2_LO) - hfsq) + f) + dk * LN2_HI;
}

double nk_power(double x, double y) {
    if (!(x >= 0.0)) return NAN; /* Python raises */
    if (y == 0.0) return 1.0;
    if (x == 0.0) return y > 0.0 ? 0.0 : INFINITY;
    return nk_exp(y * nk_log(x));
}

double nk_hypot(double x, double y) { return sqrt(x * x + y * y); }

double nk_wrap_angle(double angle) {
    double k = floor(angle * INV_TWO_PI + 0.5);
    return (angle - k * TWO_PI_HI) - k * TWO_PI_LO;
}

double nk_round_half_even(double x) {
    /* Python's round(): half to even; rint in the default rounding mode. */
    return nearbyint(x) + 0.0; /* an int in Python: no negative zero */
}

/* math.fsum as CPython implements it (Modules/mathmodule.c, math_fsum_impl). */
int nk_fsum(const double *values, int count, double *out) {
    double p[FSUM_PARTIALS];
    int n = 0;
    double special_sum = 0.0, inf_sum = 0.0;
    double x, y, t, hi, yr, lo = 0.0;
    for (int idx = 0; idx < count; idx++) {
        x = values[idx];
        double xsave = x;
        int i, j;
        for (i = j = 0; j < n; j++) {
            y = p[j];
            if (fabs(x) < fabs(y)) {
                t = x; x = y; y = t;
            }
            hi = x + y;
            yr = hi - x;
            lo = y - yr;
            if (lo != 0.0) p[i++] = lo;
            x = hi;
        }
        n = i;
        if (x != 0.0) {
            if (!isfinite(x)) {
                /* a nonfinite x could arise either as a result of intermediate overflow,
                   or as a result of a nan or inf in the summands */
                if (isfinite(xsave)) return -1; /* intermediate overflow */
                if (isinf(xsave)) inf_sum += xsave;
                special_sum += xsave;
                n = 0; /* reset partials */
            } else {
                if (n >= FSUM_PARTIALS) return -1; /* cannot happen for doubles */
                p[n++] = x;
            }
        }
    }
    if (special_sum != 0.0) {
        if (isnan(inf_sum)) {
            *out = NAN; /* Python raises ValueError (-inf + inf) */
            return -2;
        }
        *out = special_sum;
        return 0;
    }
    hi = 0.0;
    if (n > 0) {
        hi = p[--n];
        /* sum_exact(ps, hi) from the top, stop when the sum becomes inexact. */
        while (n > 0) {
            x = hi;
            y = p[--n];
            hi = x + y;
            yr = hi - x;
            lo = y - yr;
            if (lo != 0.0) break;
        }
        /* Make half-even rounding work across multiple partials. Needed so that
           sum([1e-16, 1, 1e16]) will round-up the last digit to two instead of
           down to zero (the 1e-16 makes the 1 slightly closer to two). */
        if (n > 0 && ((lo < 0.0 && p[n - 1] < 0.0) || (lo > 0.0 && p[n - 1] > 0.0))) {
            y = lo * 2.0;
            x = hi + y;
            yr = x - hi;
            if (y == yr) hi = x;
        }
    }
    *out = hi;
    return 0;
}
