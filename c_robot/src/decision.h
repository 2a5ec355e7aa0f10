/* The decision math of the paper (robot_agent/core/decision.py, defence.py). */
#ifndef CR_DECISION_H
#define CR_DECISION_H
#include "limits.h"
#include "rng.h"


/* values / fsum(values), as decision.normalised; out may be values */
void normalised(const double *values, int n, double *out);
/* 1 if the opinion is n finite non-negative numbers with a positive peak */
int valid_opinion(const double *values, int n);
void negative_update(const double *opinion, int n, int eliminated, double alpha, double *out);
/* 0: None (every option contradicted), else 1 and out */
int mprodop(const double *const *pool, int count, int n, double *out);
int loglinear_pool(const double *const *pool, int count, int n, double neighbour_weight,
                   double *out);
void choose_pair(const double *opinion, int n, Stream *rng, int *first, int *second);
/* the option at or above threshold, or -1 */
int decided_option(const double *opinion, int n, double threshold);
/* trimmed_support: 0 None, else 1 and out */
int trimmed_support(const double *own, int n, const double *const *peers, int peer_count,
                    long trim, double *out);
#endif
