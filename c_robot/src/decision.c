#include "decision.h"

#include <math.h>

#include "messages.h"
#include "numeric.h"

void normalised(const double *values, int n, double *out) {
    double total;
    if (nk_fsum(values, n, &total) != 0) total = INFINITY; /* OverflowError */
    if (isinf(total)) {
        double peak = values[0];
        for (int i = 1; i < n; i++)
            if (values[i] > peak) peak = values[i];
        for (int i = 0; i < n; i++) out[i] = values[i] / peak;
        nk_fsum(out, n, &total);
        for (int i = 0; i < n; i++) out[i] = out[i] / total;
        return;
    }
    for (int i = 0; i < n; i++) out[i] = values[i] / total;
}

int valid_opinion(const double *values, int n) {
    if (n < 2) return 0;
    double peak = values[0];
    for (int i = 0; i < n; i++) {
        if (!isfinite(values[i]) || values[i] < 0.0) return 0;
        if (values[i] > peak) peak = values[i];
    }
    return peak > 0.0;
}

void negative_update(const double *opinion, int n, int eliminated, double alpha, double *out) {
    double values[MAX_OPTIONS], rest[MAX_OPTIONS], updated[MAX_OPTIONS];
    normalised(opinion, n, values);
    double x_eliminated = values[eliminated];
    int k = 0;
    for (int i = 0; i < n; i++)
        if (i != eliminated) rest[k++] = values[i];
    double x_rest;
    nk_fsum(rest, k, &x_rest);
    double denominator = alpha * x_eliminated + (1.0 - alpha) * x_rest;
    if (denominator <= 0.0) {
        for (int i = 0; i < n; i++) out[i] = values[i];
        return;
    }
    for (int i = 0; i < n; i++) updated[i] = (1.0 - alpha) * values[i] / denominator;
    updated[eliminated] = alpha * x_eliminated / denominator;
    normalised(updated, n, out);
}

int mprodop(const double *const *pool, int count, int n, double *out) {
    double mantissas[MAX_OPTIONS];
    long exponents[MAX_OPTIONS];
    for (int i = 0; i < n; i++) {
        mantissas[i] = 1.0;
        exponents[i] = 0;
    }
    for (int p = 0; p < count; p++)
        for (int i = 0; i < n; i++) {
            int value_exponent, exponent;
            double value_mantissa = frexp(pool[p][i], &value_exponent);
            double mantissa = frexp(mantissas[i] * value_mantissa, &exponent);
            mantissas[i] = mantissa;
            exponents[i] += value_exponent + exponent;
        }
    int any = 0;
    long top = 0;
    for (int i = 0; i < n; i++)
        if (mantissas[i] > 0.0) {
            if (!any || exponents[i] > top) top = exponents[i];
            any = 1;
        }
    if (!any) return 0;
    double product[MAX_OPTIONS];
    for (int i = 0; i < n; i++) {
        if (mantissas[i] > 0.0) {
            long shift = exponents[i] - top;
            if (shift < -100000) shift = -100000; /* ldexp gives 0 well before */
            product[i] = ldexp(mantissas[i], (int)shift);
        } else {
            product[i] = 0.0;
        }
    }
    normalised(product, n, out);
    return 1;
}

int loglinear_pool(const double *const *pool, int count, int n, double neighbour_weight,
                   double *out) {
    static double logs[MAX_OPTIONS];
    static double peaks[MAX_POOL];
    if (count > MAX_POOL) count = MAX_POOL;
    for (int p = 0; p < count; p++) {
        double peak = pool[p][0];
        for (int i = 1; i < n; i++)
            if (pool[p][i] > peak) peak = pool[p][i];
        peaks[p] = nk_log(peak);
    }
    for (int i = 0; i < n; i++) {
        double total = 0.0;
        for (int p = 0; p < count; p++) {
            double weight = p == 0 ? 1.0 : neighbour_weight;
            if (!(weight > 0.0)) continue;
            if (pool[p][i] == 0.0) {
                total = -INFINITY;
                break;
            }
            total += weight * (nk_log(pool[p][i]) - peaks[p]);
        }
        logs[i] = total;
    }
    double top = logs[0];
    for (int i = 1; i < n; i++)
        if (logs[i] > top) top = logs[i];
    if (top == -INFINITY) return 0;
    for (int i = 0; i < n; i++) out[i] = nk_exp(logs[i] - top);
    normalised(out, n, out);
    return 1;
}

static int weighted_index(const double *weights, int n, Stream *rng) {
    double total;
    nk_fsum(weights, n, &total);
    double target = stream_random(rng) * total;
    double running = 0.0;
    int last_positive = 0;
    for (int i = 0; i < n; i++)
        if (weights[i] > 0.0) {
            running += weights[i];
            last_positive = i;
            if (target < running) return i;
        }
    return last_positive;
}

void choose_pair(const double *opinion, int n, Stream *rng, int *first, int *second) {
    double values[MAX_OPTIONS];
    normalised(opinion, n, values);
    *first = weighted_index(values, n, rng);
    values[*first] = 0.0;
    double peak = values[0];
    for (int i = 1; i < n; i++)
        if (values[i] > peak) peak = values[i];
    if (peak > 0.0) {
        *second = weighted_index(values, n, rng);
    } else {
        int pick = (int)stream_randrange(rng, (uint64_t)(n - 1));
        *second = pick < *first ? pick : pick + 1; /* others = every index but first */
    }
}

int decided_option(const double *opinion, int n, double threshold) {
    double values[MAX_OPTIONS];
    normalised(opinion, n, values);
    int best = 0;
    for (int i = 1; i < n; i++)
        if (values[i] > values[best]) best = i;
    return values[best] >= threshold ? best : -1;
}

int trimmed_support(const double *own, int n, const double *const *peers, int peer_count,
                    long trim, double *out) {
    static long reports[MAX_OPTIONS];
    for (int i = 0; i < n; i++) reports[i] = 0;
    for (int p = 0; p < peer_count; p++)
        for (int i = 0; i < n; i++)
            if (peers[p][i] == 0.0) reports[i]++;
    int alive = 0;
    for (int i = 0; i < n; i++)
        if (own[i] > 0.0 && reports[i] <= trim) alive++;
    if (!alive) return 0;
    for (int i = 0; i < n; i++) out[i] = own[i] > 0.0 && reports[i] <= trim ? 1.0 / alive : 0.0;
    return 1;
}
