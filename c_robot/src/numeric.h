/* The portable numeric kernel (docs/kernel.md; bestofn_swarm/wire/numeric.py is the reference). */
#ifndef CR_NUMERIC_H
#define CR_NUMERIC_H

#define NK_PI 0x1.921fb54442d18p+1
#define NK_HALF_PI 0x1.921fb54442d18p+0
#define NK_TWO_PI 0x1.921fb54442d18p+2
#define NK_MAX_ANGLE 8.0e5

/* sincos: returns 0, or -1 when |x| > MAX_ANGLE or x is NaN (Python raises). */
int nk_sincos(double x, double *s, double *c);
double nk_sin(double x);
double nk_cos(double x);
double nk_atan2(double y, double x);
double nk_atan(double x);
double nk_exp(double x);
double nk_log(double x);
double nk_power(double x, double y);
double nk_hypot(double x, double y);
double nk_wrap_angle(double a);

/* math.fsum, CPython's algorithm (Shewchuk). Returns 0 on success; -1 on overflow
   (Python raises OverflowError "intermediate overflow in fsum"). */
int nk_fsum(const double *values, int n, double *out);
/* Python's round(x) (half to even) as a double. */
double nk_round_half_even(double x);
/* Python's min/max-free helpers */
#endif
